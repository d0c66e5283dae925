//! The error of reading a file whose contents must be of a kind (a scene, an image): it
//! could not be read, or it is not what it should be. One type for the readers that had
//! each their own identical copy ([`crate::core::scene::SceneError`] and
//! [`crate::io::image_file::ImageError`] are this type); the camera readers' error
//! ([`crate::core::camera::CameraError`]) is this one or one of the variants only cameras have.

use std::path::{Path, PathBuf};

/// A file that could not be read, or whose contents are not valid.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The file could not be opened or read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// File involved.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The file's contents are not valid.
    #[error("{path}: {message}")]
    Invalid {
        /// File involved.
        path: PathBuf,
        /// What is wrong, as one sentence.
        message: String,
    },
}

impl FileError {
    /// [`FileError::Invalid`] for `path`.
    pub fn invalid(path: &Path, message: impl Into<String>) -> Self {
        FileError::Invalid {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}
