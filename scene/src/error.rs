//! Typed errors of loading a scene. Each names the file, the item and the offending value.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{path}: cannot read: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}: not a valid glTF 2.0 file: {message}")]
    Gltf { path: PathBuf, message: String },
    #[error("{path}: buffer {index} ({uri}): {message}")]
    Buffer {
        path: PathBuf,
        index: usize,
        uri: String,
        message: String,
    },
    #[error("{path}: image {index} ({uri}): {message}")]
    Image {
        path: PathBuf,
        index: usize,
        uri: String,
        message: String,
    },
    #[error("{path}: mesh {mesh} primitive {primitive}: {message}")]
    Primitive {
        path: PathBuf,
        mesh: String,
        primitive: usize,
        message: String,
    },
}
