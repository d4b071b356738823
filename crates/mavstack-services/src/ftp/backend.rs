//! What an [`FtpServer`](super::FtpServer) serves: the [`Backend`] trait, path
//! normalisation, and [`MemoryBackend`], an in-memory tree.

use alloc::collections::BTreeMap;
use alloc::string::String;
use alloc::vec::Vec;

use super::payload::{DirEntry, EntryKind, NakCode};

/// How a [`Backend`] operation failed; each maps onto a NAK.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum BackendError {
    /// No such file or directory (NAK FileNotFound).
    #[error("no such file or directory")]
    NotFound,
    /// The target already exists (NAK FileExists).
    #[error("already exists")]
    Exists,
    /// Write protected (NAK FileProtected).
    #[error("write protected")]
    Protected,
    /// The directory is not empty (NAK FailErrno ENOTEMPTY).
    #[error("directory not empty")]
    NotEmpty,
    /// Past the backend's size limit (NAK FailErrno ENOSPC).
    #[error("no space")]
    NoSpace,
    /// A directory where a file was needed, or the other way round (NAK Fail).
    #[error("wrong kind of entry")]
    WrongKind,
    /// An operating-system error number (NAK FailErrno).
    #[error("errno {0}")]
    Errno(u8),
    /// Any other failure (NAK Fail).
    #[error("failed")]
    Fail,
}

impl BackendError {
    /// The NAK code and errno this error is reported with.
    #[must_use]
    pub const fn nak(self) -> (NakCode, Option<u8>) {
        match self {
            Self::NotFound => (NakCode::FileNotFound, None),
            Self::Exists => (NakCode::FileExists, None),
            Self::Protected => (NakCode::FileProtected, None),
            Self::NotEmpty => (NakCode::FailErrno, Some(39)),
            Self::NoSpace => (NakCode::FailErrno, Some(28)),
            Self::Errno(e) => (NakCode::FailErrno, Some(e)),
            Self::WrongKind | Self::Fail => (NakCode::Fail, None),
        }
    }
}

/// How [`Backend::open`] opens a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OpenMode {
    /// An existing file, for reading (OpenFileRO).
    Read,
    /// For writing, created if missing, contents kept (OpenFileWO).
    Write,
    /// For writing, created if missing, truncated to zero (CreateFile).
    Create,
}

/// A file tree an [`FtpServer`](super::FtpServer) serves.
///
/// Every `path` is already normalised by the server ([`normalize_path`]): relative to the
/// served root, `/`-separated, without empty, `.` or `..` components; `""` is the root.
pub trait Backend {
    /// An open file.
    type Handle;

    /// Opens a file.
    ///
    /// # Errors
    ///
    /// Whatever stops it: [`BackendError::NotFound`] for a missing file (or a missing parent
    /// when creating), [`BackendError::WrongKind`] for a directory, ...
    fn open(&mut self, path: &str, mode: OpenMode) -> Result<Self::Handle, BackendError>;
    /// Closes a file (sessions ended, timed out or reset).
    fn close(&mut self, handle: Self::Handle);
    /// An open file's size in bytes.
    ///
    /// # Errors
    ///
    /// If the file is gone or unreadable.
    fn size(&mut self, handle: &Self::Handle) -> Result<u64, BackendError>;
    /// Reads up to `buf.len()` bytes at `offset`; `Ok(0)` at or past the end.
    ///
    /// # Errors
    ///
    /// If the file is gone or unreadable.
    fn read(
        &mut self,
        handle: &Self::Handle,
        offset: u64,
        buf: &mut [u8],
    ) -> Result<usize, BackendError>;
    /// Writes `data` at `offset` (growing the file, zero filled, if needed).
    ///
    /// # Errors
    ///
    /// [`BackendError::NoSpace`] past the backend's limits, others as they come.
    fn write(
        &mut self,
        handle: &Self::Handle,
        offset: u64,
        data: &[u8],
    ) -> Result<(), BackendError>;
    /// Removes a file (not a directory).
    ///
    /// # Errors
    ///
    /// As the operation fails.
    fn remove(&mut self, path: &str) -> Result<(), BackendError>;
    /// Creates a directory (its parent must exist).
    ///
    /// # Errors
    ///
    /// As the operation fails.
    fn mkdir(&mut self, path: &str) -> Result<(), BackendError>;
    /// Removes an empty directory.
    ///
    /// # Errors
    ///
    /// As the operation fails.
    fn rmdir(&mut self, path: &str) -> Result<(), BackendError>;
    /// Renames a file or directory; `to` must not exist.
    ///
    /// # Errors
    ///
    /// As the operation fails.
    fn rename(&mut self, from: &str, to: &str) -> Result<(), BackendError>;
    /// Sets a file's length (cut or zero filled).
    ///
    /// # Errors
    ///
    /// As the operation fails.
    fn truncate(&mut self, path: &str, len: u64) -> Result<(), BackendError>;
    /// A directory's entries, in a stable order (listing offsets index into it).
    ///
    /// # Errors
    ///
    /// As the operation fails.
    fn list(&mut self, path: &str) -> Result<Vec<DirEntry>, BackendError>;
}

/// Normalises a path from a request: the bytes up to the first NUL, UTF-8, taken relative
/// to the root (a leading `/` changes nothing), empty and `.` components dropped.
///
/// # Errors
///
/// [`NakCode::Fail`] for bytes that are not UTF-8 and for any `..` component (nothing may
/// leave the root).
pub fn normalize_path(raw: &[u8]) -> Result<String, NakCode> {
    let end = raw.iter().position(|&b| b == 0).unwrap_or(raw.len());
    let text = core::str::from_utf8(&raw[..end]).map_err(|_| NakCode::Fail)?;
    let mut out = String::new();
    for part in text.split('/') {
        match part {
            "" | "." => {}
            ".." => return Err(NakCode::Fail),
            part => {
                if !out.is_empty() {
                    out.push('/');
                }
                out.push_str(part);
            }
        }
    }
    Ok(out)
}

#[derive(Clone, Debug, PartialEq, Eq)]
enum Node {
    File(Vec<u8>),
    Dir,
}

/// An in-memory file tree (no `std` needed). Files are limited to
/// [`MemoryBackend::max_file_size`] bytes each so a client cannot make it allocate
/// without bound.
#[derive(Clone, Debug)]
pub struct MemoryBackend {
    /// Every file and directory but the root, by normalised path.
    nodes: BTreeMap<String, Node>,
    max_file_size: u64,
}

impl Default for MemoryBackend {
    fn default() -> Self {
        Self::new()
    }
}

fn parent(path: &str) -> &str {
    path.rsplit_once('/').map_or("", |(p, _)| p)
}

impl MemoryBackend {
    /// An empty tree with files of at most 1 MiB.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            nodes: BTreeMap::new(),
            max_file_size: 1 << 20,
        }
    }

    /// The same with files of at most `max` bytes.
    #[must_use]
    pub const fn with_max_file_size(mut self, max: u64) -> Self {
        self.max_file_size = max;
        self
    }

    /// The largest file size accepted.
    #[must_use]
    pub const fn max_file_size(&self) -> u64 {
        self.max_file_size
    }

    /// Puts a file at `path` (normalised with [`normalize_path`]), creating its parent
    /// directories. Returns `false` (and changes nothing) if the path is refused or
    /// crosses a file.
    pub fn insert_file(&mut self, path: &str, contents: &[u8]) -> bool {
        let Ok(path) = normalize_path(path.as_bytes()) else {
            return false;
        };
        if path.is_empty() || matches!(self.nodes.get(&path), Some(Node::Dir)) {
            return false;
        }
        let mut dirs = Vec::new();
        let mut p = parent(&path);
        while !p.is_empty() {
            match self.nodes.get(p) {
                Some(Node::File(_)) => return false,
                Some(Node::Dir) => break,
                None => dirs.push(String::from(p)),
            }
            p = parent(p);
        }
        for d in dirs {
            self.nodes.insert(d, Node::Dir);
        }
        self.nodes.insert(path, Node::File(contents.to_vec()));
        true
    }

    /// The contents of the file at normalised `path`, if it is one.
    #[must_use]
    pub fn file(&self, path: &str) -> Option<&[u8]> {
        match self.nodes.get(path)? {
            Node::File(data) => Some(data),
            Node::Dir => None,
        }
    }

    /// Whether normalised `path` is a directory (`""`, the root, always is).
    #[must_use]
    pub fn is_dir(&self, path: &str) -> bool {
        path.is_empty() || matches!(self.nodes.get(path), Some(Node::Dir))
    }

    /// Every path in the tree but the root, in order.
    pub fn paths(&self) -> impl Iterator<Item = &str> {
        self.nodes.keys().map(String::as_str)
    }

    fn children<'a>(&'a self, dir: &'a str) -> impl Iterator<Item = (&'a str, &'a Node)> + 'a {
        let prefix = if dir.is_empty() {
            String::new()
        } else {
            alloc::format!("{dir}/")
        };
        self.nodes
            .range(prefix.clone()..)
            .take_while(move |(k, _)| k.starts_with(&prefix))
            .filter(move |(k, _)| parent(k) == dir)
            .map(|(k, v)| (k.as_str(), v))
    }

    fn need_parent_dir(&self, path: &str) -> Result<(), BackendError> {
        let p = parent(path);
        match self.nodes.get(p) {
            _ if p.is_empty() => Ok(()),
            Some(Node::Dir) => Ok(()),
            Some(Node::File(_)) => Err(BackendError::WrongKind),
            None => Err(BackendError::NotFound),
        }
    }

    fn file_mut(&mut self, path: &str) -> Result<&mut Vec<u8>, BackendError> {
        match self.nodes.get_mut(path) {
            Some(Node::File(data)) => Ok(data),
            Some(Node::Dir) => Err(BackendError::WrongKind),
            None if path.is_empty() => Err(BackendError::WrongKind),
            None => Err(BackendError::NotFound),
        }
    }
}

impl Backend for MemoryBackend {
    /// The file's normalised path.
    type Handle = String;

    fn open(&mut self, path: &str, mode: OpenMode) -> Result<String, BackendError> {
        match (self.nodes.get_mut(path), mode) {
            (_, _) if path.is_empty() => return Err(BackendError::WrongKind),
            (Some(Node::Dir), _) => return Err(BackendError::WrongKind),
            (Some(Node::File(data)), OpenMode::Create) => data.clear(),
            (Some(Node::File(_)), _) => {}
            (None, OpenMode::Read) => return Err(BackendError::NotFound),
            (None, _) => {
                self.need_parent_dir(path)?;
                self.nodes
                    .insert(String::from(path), Node::File(Vec::new()));
            }
        }
        Ok(String::from(path))
    }

    fn close(&mut self, _handle: String) {}

    fn size(&mut self, handle: &String) -> Result<u64, BackendError> {
        let len = self.file_mut(handle)?.len();
        Ok(u64::try_from(len).unwrap_or(u64::MAX))
    }

    fn read(
        &mut self,
        handle: &String,
        offset: u64,
        buf: &mut [u8],
    ) -> Result<usize, BackendError> {
        let data = self.file_mut(handle)?;
        let Ok(start) = usize::try_from(offset) else {
            return Ok(0);
        };
        let Some(rest) = data.get(start..) else {
            return Ok(0);
        };
        let n = rest.len().min(buf.len());
        buf[..n].copy_from_slice(&rest[..n]);
        Ok(n)
    }

    fn write(&mut self, handle: &String, offset: u64, bytes: &[u8]) -> Result<(), BackendError> {
        let max = self.max_file_size;
        let data = self.file_mut(handle)?;
        let len = u64::try_from(bytes.len()).unwrap_or(u64::MAX);
        let end = offset.checked_add(len).ok_or(BackendError::NoSpace)?;
        if end > max {
            return Err(BackendError::NoSpace);
        }
        let (start, end) = (
            usize::try_from(offset).map_err(|_| BackendError::NoSpace)?,
            usize::try_from(end).map_err(|_| BackendError::NoSpace)?,
        );
        if data.len() < end {
            data.resize(end, 0);
        }
        data[start..end].copy_from_slice(bytes);
        Ok(())
    }

    fn remove(&mut self, path: &str) -> Result<(), BackendError> {
        self.file_mut(path)?;
        self.nodes.remove(path);
        Ok(())
    }

    fn mkdir(&mut self, path: &str) -> Result<(), BackendError> {
        if path.is_empty() || self.nodes.contains_key(path) {
            return Err(BackendError::Exists);
        }
        self.need_parent_dir(path)?;
        self.nodes.insert(String::from(path), Node::Dir);
        Ok(())
    }

    fn rmdir(&mut self, path: &str) -> Result<(), BackendError> {
        match self.nodes.get(path) {
            _ if path.is_empty() => Err(BackendError::Protected),
            None => Err(BackendError::NotFound),
            Some(Node::File(_)) => Err(BackendError::WrongKind),
            Some(Node::Dir) if self.children(path).next().is_some() => Err(BackendError::NotEmpty),
            Some(Node::Dir) => {
                self.nodes.remove(path);
                Ok(())
            }
        }
    }

    fn rename(&mut self, from: &str, to: &str) -> Result<(), BackendError> {
        if from.is_empty() || to.is_empty() {
            return Err(BackendError::Protected);
        }
        if !self.nodes.contains_key(from) {
            return Err(BackendError::NotFound);
        }
        if self.nodes.contains_key(to) {
            return Err(BackendError::Exists);
        }
        let inside = alloc::format!("{from}/");
        if to.starts_with(&inside) {
            return Err(BackendError::Fail);
        }
        self.need_parent_dir(to)?;
        let moved: Vec<String> = self
            .nodes
            .range(inside.clone()..)
            .take_while(|(k, _)| k.starts_with(&inside))
            .map(|(k, _)| k.clone())
            .collect();
        for old in moved {
            if let Some(node) = self.nodes.remove(&old) {
                let new = alloc::format!("{to}/{}", &old[inside.len()..]);
                self.nodes.insert(new, node);
            }
        }
        if let Some(node) = self.nodes.remove(from) {
            self.nodes.insert(String::from(to), node);
        }
        Ok(())
    }

    fn truncate(&mut self, path: &str, len: u64) -> Result<(), BackendError> {
        if len > self.max_file_size {
            return Err(BackendError::NoSpace);
        }
        let len = usize::try_from(len).map_err(|_| BackendError::NoSpace)?;
        self.file_mut(path)?.resize(len, 0);
        Ok(())
    }

    fn list(&mut self, path: &str) -> Result<Vec<DirEntry>, BackendError> {
        match self.nodes.get(path) {
            Some(Node::File(_)) => return Err(BackendError::WrongKind),
            None if !path.is_empty() => return Err(BackendError::NotFound),
            _ => {}
        }
        Ok(self
            .children(path)
            .map(|(k, node)| DirEntry {
                name: String::from(k.rsplit('/').next().unwrap_or(k)),
                kind: match node {
                    Node::File(data) => EntryKind::File {
                        size: u64::try_from(data.len()).unwrap_or(u64::MAX),
                    },
                    Node::Dir => EntryKind::Directory,
                },
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_are_normalised_and_never_leave_the_root() {
        assert_eq!(normalize_path(b"/a//b/./c\0junk").as_deref(), Ok("a/b/c"));
        assert_eq!(normalize_path(b"").as_deref(), Ok(""));
        assert_eq!(normalize_path(b"/").as_deref(), Ok(""));
        assert_eq!(normalize_path(b"a/../b"), Err(NakCode::Fail));
        assert_eq!(normalize_path(b"../etc/passwd"), Err(NakCode::Fail));
        assert_eq!(normalize_path(b"\xff"), Err(NakCode::Fail));
    }

    #[test]
    fn memory_tree_operations() {
        let mut m = MemoryBackend::new().with_max_file_size(100);
        assert!(m.insert_file("d/e/f.txt", b"hello"));
        assert!(m.is_dir("d/e"));
        assert_eq!(m.rmdir("d"), Err(BackendError::NotEmpty));
        m.rename("d", "x").unwrap();
        assert_eq!(m.file("x/e/f.txt"), Some(&b"hello"[..]));
        assert!(m.file("d/e/f.txt").is_none());
        let h = m.open("x/e/f.txt", OpenMode::Write).unwrap();
        assert_eq!(m.write(&h, 99, b"ab"), Err(BackendError::NoSpace));
        m.write(&h, 7, b"!").unwrap();
        assert_eq!(m.file("x/e/f.txt"), Some(&b"hello\0\0!"[..]));
        assert_eq!(
            m.open("nope/f", OpenMode::Create),
            Err(BackendError::NotFound)
        );
        assert_eq!(m.list("x").unwrap().len(), 1);
        assert_eq!(m.rename("x", "x/e/y"), Err(BackendError::Fail));
    }
}
