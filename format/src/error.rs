//! Typed errors of loading and validating an asset. Every message carries the offending value.

use std::path::PathBuf;

/// Why an asset could not be read, written or accepted.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    #[error("{path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("not a regular file; refusing to replace it (write to a file path instead)")]
    NotARegularFile { path: PathBuf },
    #[error("{path}: the output's directory {dir} does not exist or is not a directory")]
    NoOutputDirectory { path: PathBuf, dir: PathBuf },
    #[error(
        "not a prt asset: the file is {len} bytes, shorter than the {min}-byte header and checksum"
    )]
    TooShort { len: usize, min: usize },
    #[error("not a prt asset: magic bytes are {found:02x?}, expected {expected:02x?}")]
    BadMagic { found: [u8; 8], expected: [u8; 8] },
    #[error("unsupported format version {found} (this build reads version {supported}): re-bake the scene with this build's `prt bake`")]
    UnsupportedVersion { found: u32, supported: u32 },
    #[error("truncated or padded asset: header declares a {declared}-byte payload, the file holds {actual}")]
    LengthMismatch { declared: u64, actual: u64 },
    #[error("checksum mismatch: stored {stored:#018x}, computed {computed:#018x} (the file is corrupted)")]
    Checksum { stored: u64, computed: u64 },
    #[error("section {section} (payload byte {offset}) does not decode: {message}")]
    Decode {
        section: &'static str,
        offset: usize,
        message: String,
    },
    #[error("payload does not encode: {0}")]
    Encode(String),
    #[error("{payload_bytes} bytes of payload left over after decoding the asset")]
    TrailingBytes { payload_bytes: usize },
    #[error("invalid asset: {section}[{index}]: {what}")]
    Invalid {
        section: &'static str,
        index: usize,
        what: String,
    },
    #[error("invalid asset: {section} has {found} entries, expected {expected}")]
    Count {
        section: &'static str,
        found: usize,
        expected: usize,
    },
}

impl FormatError {
    pub(crate) fn invalid(section: &'static str, index: usize, what: impl Into<String>) -> Self {
        FormatError::Invalid {
            section,
            index,
            what: what.into(),
        }
    }
}
