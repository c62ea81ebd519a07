//! Binary encoding of an [`Asset`] and atomic writing.
//!
//! Layout (all integers little-endian):
//!
//! | bytes | content |
//! |---|---|
//! | 0..8 | [`MAGIC`] (`PRTGI`, a NUL and CR LF: text-mode transfers that mangle line ends are caught) |
//! | 8..12 | [`FORMAT_VERSION`] |
//! | 12..20 | payload length L |
//! | 20..20+L | payload: the asset, serde + bincode 2, fixed-width little-endian integers |
//! | 20+L..28+L | xxh3-64 of bytes 0..20+L |
//!
//! The checksum is verified before anything is decoded, so a flipped byte or a truncated file is
//! reported as such instead of as a confusing decode error; decoding then runs under a size limit
//! and the result is validated ([`crate::validate`]).

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::asset::Asset;
use crate::error::FormatError;

/// The first eight bytes of every prt asset.
pub const MAGIC: [u8; 8] = *b"PRTGI\0\r\n";
/// Version of the layout this build writes and reads. Bump on any change of the payload types.
pub const FORMAT_VERSION: u32 = 3;

const PREFIX: usize = 20;
const SUFFIX: usize = 8;

fn config() -> bincode::config::Configuration<bincode::config::LittleEndian, bincode::config::Fixint>
{
    bincode::config::standard()
        .with_little_endian()
        .with_fixed_int_encoding()
}

/// Serializes an asset into the bytes of a `.prt` file.
pub fn encode(asset: &Asset) -> Result<Vec<u8>, FormatError> {
    let payload = bincode::serde::encode_to_vec(asset, config())
        .map_err(|e| FormatError::Encode(e.to_string()))?;
    let mut out = Vec::with_capacity(PREFIX + payload.len() + SUFFIX);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&payload);
    let checksum = xxhash_rust::xxh3::xxh3_64(&out);
    out.extend_from_slice(&checksum.to_le_bytes());
    Ok(out)
}

/// Parses and validates the bytes of a `.prt` file. Never panics, whatever the bytes.
pub fn decode(bytes: &[u8]) -> Result<Asset, FormatError> {
    if bytes.len() < PREFIX + SUFFIX {
        return Err(FormatError::TooShort {
            len: bytes.len(),
            min: PREFIX + SUFFIX,
        });
    }
    let mut magic = [0u8; 8];
    magic.copy_from_slice(&bytes[0..8]);
    if magic != MAGIC {
        return Err(FormatError::BadMagic {
            found: magic,
            expected: MAGIC,
        });
    }
    let version = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
    if version != FORMAT_VERSION {
        return Err(FormatError::UnsupportedVersion {
            found: version,
            supported: FORMAT_VERSION,
        });
    }
    let mut len = [0u8; 8];
    len.copy_from_slice(&bytes[12..20]);
    let declared = u64::from_le_bytes(len);
    let actual = (bytes.len() - PREFIX - SUFFIX) as u64;
    if declared != actual {
        return Err(FormatError::LengthMismatch { declared, actual });
    }
    let body_end = bytes.len() - SUFFIX;
    let mut stored = [0u8; 8];
    stored.copy_from_slice(&bytes[body_end..]);
    let stored = u64::from_le_bytes(stored);
    let computed = xxhash_rust::xxh3::xxh3_64(&bytes[..body_end]);
    if stored != computed {
        return Err(FormatError::Checksum { stored, computed });
    }
    let payload = &bytes[PREFIX..body_end];
    let (asset, used): (Asset, usize) =
        bincode::serde::decode_from_slice(payload, config().with_limit::<{ 1 << 36 }>())
            .map_err(|e| FormatError::Decode(e.to_string()))?;
    if used != payload.len() {
        return Err(FormatError::TrailingBytes {
            payload_bytes: payload.len() - used,
        });
    }
    crate::validate::validate(&asset)?;
    Ok(asset)
}

/// Reads and validates an asset file.
pub fn read_asset(path: &Path) -> Result<Asset, FormatError> {
    let bytes = std::fs::read(path).map_err(|error| FormatError::Io {
        path: path.to_owned(),
        error,
    })?;
    decode(&bytes)
}

/// Writes an asset atomically: to a temporary file beside `path`, flushed to disk, then renamed
/// over `path`. A failure leaves no partial file behind. Returns the number of bytes written.
pub fn write_asset_atomic(path: &Path, asset: &Asset) -> Result<u64, FormatError> {
    let bytes = encode(asset)?;
    write_bytes_atomic(path, &bytes)?;
    Ok(bytes.len() as u64)
}

/// Fails when `path` exists and is not a regular file: the atomic rename would replace a device
/// (`/dev/null` as root), a directory entry or a pipe with a regular file.
pub fn check_replaceable(path: &Path) -> Result<(), FormatError> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if !m.file_type().is_file() => {
            // A symlink to a regular file is replaced by the rename, not followed: refuse it
            // too, rather than break the link silently.
            Err(FormatError::NotARegularFile {
                path: path.to_owned(),
            })
        }
        _ => Ok(()),
    }
}

/// Whether `a` and `b` name the same existing file (after resolving links and `..`).
pub fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// Writes `bytes` to `path` through a temporary file and a rename.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<(), FormatError> {
    check_replaceable(path)?;
    let io_err = |p: &Path| {
        let p = p.to_owned();
        move |error| FormatError::Io { path: p, error }
    };
    let tmp = temp_path(path);
    let result = (|| {
        let mut f = std::fs::File::create(&tmp).map_err(io_err(&tmp))?;
        f.write_all(bytes).map_err(io_err(&tmp))?;
        f.sync_all().map_err(io_err(&tmp))?;
        drop(f);
        std::fs::rename(&tmp, path).map_err(io_err(path))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

fn temp_path(path: &Path) -> PathBuf {
    let mut name = path
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(format!(".tmp{}", std::process::id()));
    path.with_file_name(name)
}
