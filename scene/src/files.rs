//! Where a scene's external files may lie: in the scene file's folder or a folder the caller
//! allows ([`Allowed`]), judged on the canonical path (`..` and symlinks resolved). Without
//! this a glTF's `"uri": "../../../../etc/hostname"`, an absolute path or a symlink out of the
//! folder is opened, and a file whose length matches its `byteLength` ends up in the asset a
//! content pipeline ships.

use std::path::{Path, PathBuf};

use crate::error::SceneError;

/// Folders besides the scene file's own that its buffer and image URIs may reach, such as a
/// shared texture folder (`prt bake --allow-path DIR`, repeatable). The default allows none:
/// only the scene's folder and what lies below it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Allowed {
    pub dirs: Vec<PathBuf>,
}

/// The folders a scene's external files may lie in. They are made canonical only when a URI
/// names a file: a scene without external files loads from bytes whatever its path.
pub(crate) struct Folders<'a> {
    /// Where relative URIs are resolved from: the scene file's folder as given.
    base: PathBuf,
    allowed: &'a Allowed,
}

impl<'a> Folders<'a> {
    /// The folder of the scene file `path`, and `allowed`.
    pub fn of(path: &Path, allowed: &'a Allowed) -> Folders<'a> {
        let base = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
            _ => PathBuf::from("."),
        };
        Folders { base, allowed }
    }

    /// The folder relative URIs are resolved from (the scene file's, as given).
    pub fn base(&self) -> &Path {
        &self.base
    }

    /// The canonical regular file that the (not data) `uri` names, relative to the scene's
    /// folder or absolute, or why it is refused: a scheme, a missing file, a file outside the
    /// scene's folder and the allowed ones, or not a regular file (a device, a directory, a
    /// FIFO).
    pub fn resolve(&self, uri: &str) -> Result<PathBuf, String> {
        let decoded = percent_decode(uri);
        // A colon is a scheme (`file:`, `http:`) or a drive letter.
        if decoded.contains(':') {
            return Err(format!(
                "URI {uri:?} has a scheme; only data URIs and file paths are read"
            ));
        }
        let joined = self.base.join(&decoded);
        let file = joined
            .canonicalize()
            .map_err(|e| format!("file {} not found ({e})", joined.display()))?;
        let canonical = |dir: &Path| {
            dir.canonicalize()
                .map_err(|e| format!("folder {}: {e}", dir.display()))
        };
        let scene = canonical(&self.base)?;
        // Allowed folders that do not resolve are named in the refusal (a typo in a flag).
        let mut unresolved = String::new();
        let allowed = |dir: &PathBuf| match canonical(dir) {
            Ok(dir) => file.starts_with(dir),
            Err(e) => {
                unresolved.push_str(&format!("; allowed {e}"));
                false
            }
        };
        if !file.starts_with(&scene) && !self.allowed.dirs.iter().any(allowed) {
            return Err(format!(
                "{} lies outside the scene's folder {}{}; allow its folder with --allow-path DIR (prt_scene::Allowed){unresolved}",
                file.display(),
                scene.display(),
                if self.allowed.dirs.is_empty() {
                    ""
                } else {
                    " and the allowed folders"
                }
            ));
        }
        match std::fs::metadata(&file) {
            Ok(m) if m.is_file() => Ok(file),
            Ok(_) => Err(format!("{} is not a regular file", file.display())),
            Err(e) => Err(format!("file {} not found ({e})", file.display())),
        }
    }
}

/// `%XX` escapes decoded (glTF URIs are RFC 3986 references); invalid escapes stay as they are.
fn percent_decode(uri: &str) -> String {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The bytes of buffer `index`'s checked external `file` as the gltf crate's importer gives
/// them (the whole file, zero-padded to a multiple of 4 bytes), or why not: it could not be
/// read, or it no longer holds `byte_length` bytes.
pub(crate) fn read_buffer(
    path: &Path,
    index: usize,
    uri: &str,
    file: &Path,
    byte_length: usize,
) -> Result<gltf::buffer::Data, SceneError> {
    let fail = |message: String| SceneError::Buffer {
        path: path.to_owned(),
        index,
        uri: uri.to_owned(),
        message,
    };
    let mut data = prt_format::io::read_regular_file(file)
        .map_err(|e| fail(format!("{}: {e}", file.display())))?;
    if data.len() < byte_length {
        return Err(fail(format!(
            "the file has {} bytes, byteLength says {byte_length}",
            data.len()
        )));
    }
    data.resize(data.len().next_multiple_of(4), 0);
    Ok(gltf::buffer::Data(data))
}
