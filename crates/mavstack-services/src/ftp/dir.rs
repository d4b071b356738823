//! [`DirBackend`]: a [`Backend`] over a real directory (needs `std`).

use alloc::string::String;
use alloc::vec::Vec;
use std::ffi::OsString;
use std::fs::{self, File, OpenOptions};
use std::io::{self, ErrorKind, Read, Seek, SeekFrom, Write};
use std::path::{Component, Path, PathBuf};

use super::backend::{Backend, BackendError, OpenMode, normalize_path};
use super::payload::{DirEntry, EntryKind};

/// The default [`DirBackend::max_file_size`]: 64 MiB.
pub const DEFAULT_MAX_FILE_SIZE: u64 = 64 << 20;

/// A [`Backend`] serving a directory of the local file system.
///
/// - Read-only unless made [`writable`](Self::writable): until then opening for writing,
///   removing, creating or removing directories, renaming and truncating are refused with
///   [`BackendError::Protected`] (NAK FileProtected).
/// - Nothing outside the root is read, written, listed or created. Paths are normalised
///   again with [`normalize_path`] (`..` is refused with [`BackendError::Fail`], as the
///   server does), joined to the canonical root, and the existing part is canonicalised
///   (symbolic links resolved) before every operation; a resolved path outside the root is
///   refused with [`BackendError::Protected`]. Operations on an entry itself (remove,
///   rename, rmdir, mkdir, creating a file) resolve its parent and act on the name in it,
///   so a symbolic link is removed or renamed, never what it points to; a file is created
///   with `O_EXCL`-like semantics so a dangling link is not followed out of the root.
/// - Writes and truncations past [`max_file_size`](Self::max_file_size) are refused with
///   [`BackendError::NoSpace`].
/// - Listings are sorted by name: files with their size, directories, and skip entries
///   for anything else (sockets, devices, links leading outside the root or nowhere) and
///   for names that are not UTF-8. Symbolic links inside the root are listed as what they
///   lead to.
/// - I/O errors map to NAKs: not found → FileNotFound, already exists → FileExists,
///   permission denied → FileProtected, directory not empty → FailErrno ENOTEMPTY,
///   anything else with an OS error number → FailErrno with it, the rest → Fail.
///
/// Checks and operations are separate system calls: someone changing the tree on the
/// machine itself between them (swapping a directory for a link) can race them. FTP
/// clients cannot create links.
#[derive(Clone, Debug)]
pub struct DirBackend {
    root: PathBuf,
    writable: bool,
    max_file_size: u64,
}

/// Maps an I/O error onto the NAK it is reported with.
fn io_err(e: &io::Error) -> BackendError {
    match e.kind() {
        ErrorKind::NotFound => BackendError::NotFound,
        ErrorKind::AlreadyExists => BackendError::Exists,
        ErrorKind::PermissionDenied => BackendError::Protected,
        ErrorKind::DirectoryNotEmpty => BackendError::NotEmpty,
        ErrorKind::IsADirectory | ErrorKind::NotADirectory => BackendError::WrongKind,
        _ => e
            .raw_os_error()
            .and_then(|n| u8::try_from(n).ok())
            .map_or(BackendError::Fail, BackendError::Errno),
    }
}

fn len_u64(n: usize) -> u64 {
    u64::try_from(n).unwrap_or(u64::MAX)
}

impl DirBackend {
    /// A read-only backend serving `root`, which must exist and be a directory; it is
    /// canonicalised once, here. Files are limited to [`DEFAULT_MAX_FILE_SIZE`] bytes.
    ///
    /// # Errors
    ///
    /// If `root` cannot be canonicalised (it does not exist, ...) or is not a directory;
    /// the message names the path.
    pub fn new(root: impl Into<PathBuf>) -> io::Result<Self> {
        let given = root.into();
        let root = fs::canonicalize(&given).map_err(|e| {
            io::Error::new(
                e.kind(),
                alloc::format!("FTP root {}: {e}", given.display()),
            )
        })?;
        let meta = fs::metadata(&root).map_err(|e| {
            io::Error::new(
                e.kind(),
                alloc::format!("FTP root {}: {e}", given.display()),
            )
        })?;
        if !meta.is_dir() {
            return Err(io::Error::new(
                ErrorKind::NotADirectory,
                alloc::format!("FTP root {}: not a directory", given.display()),
            ));
        }
        Ok(Self {
            root,
            writable: false,
            max_file_size: DEFAULT_MAX_FILE_SIZE,
        })
    }

    /// The same, allowing changes: creating, writing, removing, renaming and truncating
    /// files, creating and removing directories.
    #[must_use]
    pub const fn writable(mut self) -> Self {
        self.writable = true;
        self
    }

    /// The same with files of at most `max` bytes (writes and truncations past it are
    /// refused).
    #[must_use]
    pub const fn with_max_file_size(mut self, max: u64) -> Self {
        self.max_file_size = max;
        self
    }

    /// The canonical root served.
    #[must_use]
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Whether changes are allowed.
    #[must_use]
    pub const fn is_writable(&self) -> bool {
        self.writable
    }

    /// The largest file size accepted.
    #[must_use]
    pub const fn max_file_size(&self) -> u64 {
        self.max_file_size
    }

    const fn need_writable(&self) -> Result<(), BackendError> {
        if self.writable {
            Ok(())
        } else {
            Err(BackendError::Protected)
        }
    }

    /// The root joined with normalised `path`, each component a plain name.
    fn join(&self, path: &str) -> Result<PathBuf, BackendError> {
        let path = normalize_path(path.as_bytes()).map_err(|_| BackendError::Fail)?;
        let mut out = self.root.clone();
        if path.is_empty() {
            return Ok(out);
        }
        for part in path.split('/') {
            let mut components = Path::new(part).components();
            match (components.next(), components.next()) {
                (Some(Component::Normal(name)), None) if name == part => out.push(name),
                _ => return Err(BackendError::Fail),
            }
        }
        Ok(out)
    }

    fn inside(&self, resolved: &Path) -> Result<(), BackendError> {
        if resolved.starts_with(&self.root) {
            Ok(())
        } else {
            Err(BackendError::Protected)
        }
    }

    /// `path` with every symbolic link resolved, refused unless inside the root.
    fn resolve(&self, path: &str) -> Result<PathBuf, BackendError> {
        let joined = self.join(path)?;
        match fs::canonicalize(&joined) {
            Ok(resolved) => {
                self.inside(&resolved)?;
                Ok(resolved)
            }
            Err(e) => {
                // Say nothing about what lies outside: if the longest existing prefix
                // resolves outside the root, that is the answer.
                let mut up = joined.parent();
                while let Some(dir) = up {
                    if dir == self.root || !dir.starts_with(&self.root) {
                        break;
                    }
                    if let Ok(resolved) = fs::canonicalize(dir) {
                        self.inside(&resolved)?;
                        break;
                    }
                    up = dir.parent();
                }
                Err(io_err(&e))
            }
        }
    }

    /// For an operation on the entry `path` itself: its resolved parent directory
    /// (inside the root) joined with its name, no link in the last component followed.
    fn entry(&self, path: &str) -> Result<PathBuf, BackendError> {
        let path = normalize_path(path.as_bytes()).map_err(|_| BackendError::Fail)?;
        if path.is_empty() {
            return Err(BackendError::Protected);
        }
        let (parent, name) = path.rsplit_once('/').unwrap_or(("", &path));
        let dir = self.resolve(parent)?;
        if !fs::metadata(&dir).map_err(|e| io_err(&e))?.is_dir() {
            return Err(BackendError::WrongKind);
        }
        // `join` checks the name is one plain component.
        let name = self.join(name)?;
        let name = name.file_name().ok_or(BackendError::Fail)?;
        Ok(dir.join(name))
    }

    /// A regular file at resolved `path` (inside the root).
    fn resolve_file(&self, path: &str) -> Result<PathBuf, BackendError> {
        let resolved = self.resolve(path)?;
        if fs::metadata(&resolved).map_err(|e| io_err(&e))?.is_file() {
            Ok(resolved)
        } else {
            Err(BackendError::WrongKind)
        }
    }

    /// Opens for writing, creating the file if missing.
    fn open_write(&self, path: &str, truncate: bool) -> Result<File, BackendError> {
        let target = self.entry(path)?;
        let existing = match fs::symlink_metadata(&target) {
            Ok(meta) => Some(meta),
            Err(e) if e.kind() == ErrorKind::NotFound => None,
            Err(e) => return Err(io_err(&e)),
        };
        let Some(meta) = existing else {
            // Exclusive creation: fails on anything already there, a dangling link
            // included, rather than following it.
            return OpenOptions::new()
                .read(true)
                .write(true)
                .create_new(true)
                .open(&target)
                .map_err(|e| io_err(&e));
        };
        let target = if meta.file_type().is_symlink() {
            // Followed only to a file inside the root.
            self.resolve_file(path)?
        } else if meta.is_file() {
            target
        } else {
            return Err(BackendError::WrongKind);
        };
        OpenOptions::new()
            .read(true)
            .write(true)
            .truncate(truncate)
            .open(&target)
            .map_err(|e| io_err(&e))
    }

    fn describe(&self, path: &Path, file_type: fs::FileType) -> EntryKind {
        let meta = if file_type.is_symlink() {
            match fs::canonicalize(path) {
                Ok(resolved) if self.inside(&resolved).is_ok() => fs::metadata(&resolved),
                _ => return EntryKind::Skip,
            }
        } else {
            fs::symlink_metadata(path)
        };
        match meta {
            Ok(m) if m.is_file() => EntryKind::File { size: m.len() },
            Ok(m) if m.is_dir() => EntryKind::Directory,
            _ => EntryKind::Skip,
        }
    }
}

impl Backend for DirBackend {
    /// The open file.
    type Handle = File;

    fn open(&mut self, path: &str, mode: OpenMode) -> Result<File, BackendError> {
        match mode {
            OpenMode::Read => {
                let resolved = self.resolve_file(path)?;
                File::open(resolved).map_err(|e| io_err(&e))
            }
            OpenMode::Write => {
                self.need_writable()?;
                self.open_write(path, false)
            }
            OpenMode::Create => {
                self.need_writable()?;
                self.open_write(path, true)
            }
        }
    }

    fn close(&mut self, handle: File) {
        drop(handle);
    }

    fn size(&mut self, handle: &File) -> Result<u64, BackendError> {
        handle.metadata().map(|m| m.len()).map_err(|e| io_err(&e))
    }

    fn read(&mut self, handle: &File, offset: u64, buf: &mut [u8]) -> Result<usize, BackendError> {
        let mut file = handle;
        file.seek(SeekFrom::Start(offset)).map_err(|e| io_err(&e))?;
        let mut done = 0;
        while done < buf.len() {
            match file.read(&mut buf[done..]) {
                Ok(0) => break,
                Ok(n) => done += n,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(io_err(&e)),
            }
        }
        Ok(done)
    }

    fn write(&mut self, handle: &File, offset: u64, data: &[u8]) -> Result<(), BackendError> {
        self.need_writable()?;
        let end = offset
            .checked_add(len_u64(data.len()))
            .ok_or(BackendError::NoSpace)?;
        if end > self.max_file_size {
            return Err(BackendError::NoSpace);
        }
        let mut file = handle;
        file.seek(SeekFrom::Start(offset)).map_err(|e| io_err(&e))?;
        file.write_all(data).map_err(|e| io_err(&e))
    }

    fn remove(&mut self, path: &str) -> Result<(), BackendError> {
        self.need_writable()?;
        let target = self.entry(path)?;
        let meta = fs::symlink_metadata(&target).map_err(|e| io_err(&e))?;
        if meta.is_dir() {
            return Err(BackendError::WrongKind);
        }
        // A link is removed itself, whatever it leads to.
        fs::remove_file(&target).map_err(|e| io_err(&e))
    }

    fn mkdir(&mut self, path: &str) -> Result<(), BackendError> {
        self.need_writable()?;
        if normalize_path(path.as_bytes()).is_ok_and(|p| p.is_empty()) {
            return Err(BackendError::Exists);
        }
        let target = self.entry(path)?;
        // mkdir does not follow a link in the last component: it reports it exists.
        fs::create_dir(&target).map_err(|e| io_err(&e))
    }

    fn rmdir(&mut self, path: &str) -> Result<(), BackendError> {
        self.need_writable()?;
        let target = self.entry(path)?;
        let meta = fs::symlink_metadata(&target).map_err(|e| io_err(&e))?;
        if !meta.is_dir() {
            return Err(BackendError::WrongKind);
        }
        fs::remove_dir(&target).map_err(|e| io_err(&e))
    }

    fn rename(&mut self, from: &str, to: &str) -> Result<(), BackendError> {
        self.need_writable()?;
        let old = self.entry(from)?;
        let new = self.entry(to)?;
        fs::symlink_metadata(&old).map_err(|e| io_err(&e))?;
        match fs::symlink_metadata(&new) {
            Ok(_) => return Err(BackendError::Exists),
            Err(e) if e.kind() == ErrorKind::NotFound => {}
            Err(e) => return Err(io_err(&e)),
        }
        fs::rename(&old, &new).map_err(|e| io_err(&e))
    }

    fn truncate(&mut self, path: &str, len: u64) -> Result<(), BackendError> {
        self.need_writable()?;
        if len > self.max_file_size {
            return Err(BackendError::NoSpace);
        }
        let resolved = self.resolve_file(path)?;
        let file = OpenOptions::new()
            .write(true)
            .open(resolved)
            .map_err(|e| io_err(&e))?;
        file.set_len(len).map_err(|e| io_err(&e))
    }

    fn list(&mut self, path: &str) -> Result<Vec<DirEntry>, BackendError> {
        let dir = self.resolve(path)?;
        if !fs::metadata(&dir).map_err(|e| io_err(&e))?.is_dir() {
            return Err(BackendError::WrongKind);
        }
        let mut found: Vec<(OsString, EntryKind)> = Vec::new();
        for entry in fs::read_dir(&dir).map_err(|e| io_err(&e))? {
            let Ok(entry) = entry else {
                continue;
            };
            let kind = match entry.file_type() {
                Ok(t) => self.describe(&entry.path(), t),
                Err(_) => EntryKind::Skip,
            };
            found.push((entry.file_name(), kind));
        }
        found.sort_by(|a, b| a.0.cmp(&b.0));
        Ok(found
            .into_iter()
            .map(|(name, kind)| match (name.into_string(), kind) {
                (Ok(name), kind @ (EntryKind::File { .. } | EntryKind::Directory)) => {
                    DirEntry { name, kind }
                }
                _ => DirEntry {
                    name: String::new(),
                    kind: EntryKind::Skip,
                },
            })
            .collect())
    }
}

#[cfg(all(test, unix))]
mod tests {
    use alloc::string::ToString;
    use alloc::vec;
    use core::time::Duration;
    use std::os::unix::fs::symlink;

    use mavstack_core::time::Instant;

    use super::super::client::{ClientConfig, FtpClient, FtpError, FtpEvent, FtpOutput};
    use super::super::payload::{NakCode, crc32};
    use super::super::server::{FtpServer, ServerConfig};
    use super::*;
    use crate::{Address, Service};

    const GCS: Address = Address::new(255, 190);
    const VEHICLE: Address = Address::new(1, 1);

    /// A served directory inside a temporary one, and a sibling outside it.
    fn setup() -> (tempfile::TempDir, PathBuf, PathBuf) {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("root");
        let outside = tmp.path().join("outside");
        fs::create_dir(&root).unwrap();
        fs::create_dir(&outside).unwrap();
        fs::write(outside.join("secret.txt"), b"secret").unwrap();
        (tmp, root, outside)
    }

    fn read_all(b: &mut DirBackend, path: &str) -> Result<Vec<u8>, BackendError> {
        let h = b.open(path, OpenMode::Read)?;
        let mut out = Vec::new();
        let mut buf = [0u8; 7];
        loop {
            let n = b.read(&h, len_u64(out.len()), &mut buf)?;
            if n == 0 {
                break;
            }
            out.extend_from_slice(&buf[..n]);
        }
        b.close(h);
        Ok(out)
    }

    /// Every file and directory under `dir`, with file contents.
    fn snapshot(dir: &Path) -> Vec<(PathBuf, Option<Vec<u8>>)> {
        let mut out = Vec::new();
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            for e in fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                let meta = fs::symlink_metadata(&p).unwrap();
                if meta.is_dir() {
                    stack.push(p.clone());
                    out.push((p, None));
                } else {
                    let data = fs::read(&p).ok();
                    out.push((p, data));
                }
            }
        }
        out.sort();
        out
    }

    #[test]
    fn root_must_be_an_existing_directory() {
        let (tmp, root, _) = setup();
        let missing = tmp.path().join("missing");
        let e = DirBackend::new(&missing).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::NotFound);
        assert!(e.to_string().contains("missing"), "{e}");
        let file = tmp.path().join("plain");
        fs::write(&file, b"x").unwrap();
        let e = DirBackend::new(&file).unwrap_err();
        assert!(e.to_string().contains("plain"), "{e}");
        let b = DirBackend::new(root.join(".")).unwrap();
        assert_eq!(b.root(), fs::canonicalize(&root).unwrap());
        assert!(!b.is_writable());
        assert_eq!(b.max_file_size(), DEFAULT_MAX_FILE_SIZE);
    }

    #[test]
    fn read_only_refuses_every_change() {
        let (_tmp, root, _) = setup();
        fs::create_dir(root.join("d")).unwrap();
        fs::write(root.join("f.txt"), b"hello").unwrap();
        let before = snapshot(&root);
        let mut b = DirBackend::new(&root).unwrap();
        let p = Err(BackendError::Protected);
        assert_eq!(b.open("f.txt", OpenMode::Write).map(drop), p);
        assert_eq!(b.open("new.txt", OpenMode::Create).map(drop), p);
        assert_eq!(b.remove("f.txt"), p);
        assert_eq!(b.mkdir("e"), p);
        assert_eq!(b.rmdir("d"), p);
        assert_eq!(b.rename("f.txt", "g.txt"), p);
        assert_eq!(b.truncate("f.txt", 0), p);
        // A read handle cannot write either.
        let h = b.open("f.txt", OpenMode::Read).unwrap();
        assert_eq!(b.write(&h, 0, b"x"), p);
        assert_eq!(b.size(&h), Ok(5));
        b.close(h);
        assert_eq!(BackendError::Protected.nak().0, NakCode::FileProtected);
        assert_eq!(read_all(&mut b, "/f.txt"), Ok(b"hello".to_vec()));
        assert_eq!(snapshot(&root), before);
    }

    #[test]
    fn writable_tree_operations() {
        let (_tmp, root, _) = setup();
        let mut b = DirBackend::new(&root)
            .unwrap()
            .writable()
            .with_max_file_size(100);
        assert_eq!(b.mkdir("a"), Ok(()));
        assert_eq!(b.mkdir("a"), Err(BackendError::Exists));
        assert_eq!(b.mkdir(""), Err(BackendError::Exists));
        assert_eq!(b.mkdir("x/y"), Err(BackendError::NotFound));
        assert_eq!(b.mkdir("a/b c"), Ok(()));
        let h = b.open("a/b c/f.txt", OpenMode::Create).unwrap();
        assert_eq!(b.write(&h, 0, b"hello"), Ok(()));
        assert_eq!(b.write(&h, 7, b"!"), Ok(()));
        assert_eq!(b.write(&h, 99, b"ab"), Err(BackendError::NoSpace));
        assert_eq!(b.write(&h, u64::MAX, b"ab"), Err(BackendError::NoSpace));
        assert_eq!(b.size(&h), Ok(8));
        b.close(h);
        assert_eq!(
            fs::read(root.join("a/b c/f.txt")).unwrap(),
            b"hello\0\0!".to_vec()
        );
        assert_eq!(read_all(&mut b, "a/b c/f.txt"), Ok(b"hello\0\0!".to_vec()));
        // Write keeps contents, Create truncates.
        let h = b.open("a/b c/f.txt", OpenMode::Write).unwrap();
        assert_eq!(b.size(&h), Ok(8));
        b.close(h);
        assert_eq!(b.truncate("a/b c/f.txt", 2), Ok(()));
        assert_eq!(b.truncate("a/b c/f.txt", 101), Err(BackendError::NoSpace));
        assert_eq!(read_all(&mut b, "a/b c/f.txt"), Ok(b"he".to_vec()));
        assert_eq!(
            b.open("nope/f", OpenMode::Create).map(drop),
            Err(BackendError::NotFound)
        );
        assert_eq!(
            b.open("a", OpenMode::Read).map(drop),
            Err(BackendError::WrongKind)
        );
        assert_eq!(
            b.open("", OpenMode::Read).map(drop),
            Err(BackendError::WrongKind)
        );
        assert_eq!(
            b.open("missing", OpenMode::Read).map(drop),
            Err(BackendError::NotFound)
        );
        assert_eq!(b.rmdir("a"), Err(BackendError::NotEmpty));
        assert_eq!(b.remove("a"), Err(BackendError::WrongKind));
        assert_eq!(b.rename("a", "z"), Ok(()));
        assert_eq!(read_all(&mut b, "z/b c/f.txt"), Ok(b"he".to_vec()));
        assert!(!root.join("a").exists());
        fs::write(root.join("other"), b"").unwrap();
        assert_eq!(b.rename("z", "other"), Err(BackendError::Exists));
        assert_eq!(b.rename("nope", "q"), Err(BackendError::NotFound));
        assert_eq!(b.rename("", "q"), Err(BackendError::Protected));
        assert_eq!(b.remove("z/b c/f.txt"), Ok(()));
        assert_eq!(b.remove("z/b c/f.txt"), Err(BackendError::NotFound));
        assert_eq!(b.rmdir("z/b c"), Ok(()));
        assert_eq!(b.rmdir("other"), Err(BackendError::WrongKind));
        assert_eq!(b.rmdir(""), Err(BackendError::Protected));
        assert_eq!(b.rmdir("z"), Ok(()));
        assert_eq!(
            b.list("").unwrap(),
            vec![DirEntry {
                name: "other".into(),
                kind: EntryKind::File { size: 0 }
            }]
        );
    }

    #[test]
    fn listing_is_sorted_and_skips_what_it_cannot_describe() {
        let (_tmp, root, outside) = setup();
        fs::write(root.join("b.txt"), b"12345").unwrap();
        fs::create_dir(root.join("a dir")).unwrap();
        fs::write(root.join("c"), b"").unwrap();
        symlink(outside.join("secret.txt"), root.join("d-out")).unwrap();
        symlink(root.join("b.txt"), root.join("e-in")).unwrap();
        symlink(root.join("gone"), root.join("f-dangling")).unwrap();
        let _sock = std::os::unix::net::UnixListener::bind(root.join("g.sock")).unwrap();
        {
            use std::os::unix::ffi::OsStrExt;
            // Not UTF-8 (where the file system allows it).
            let _ = fs::write(root.join(std::ffi::OsStr::from_bytes(b"h\xff")), b"x");
        }
        let mut b = DirBackend::new(&root).unwrap();
        let list = b.list("/").unwrap();
        let skip = DirEntry {
            name: String::new(),
            kind: EntryKind::Skip,
        };
        let mut want = vec![
            DirEntry {
                name: "a dir".into(),
                kind: EntryKind::Directory,
            },
            DirEntry {
                name: "b.txt".into(),
                kind: EntryKind::File { size: 5 },
            },
            DirEntry {
                name: "c".into(),
                kind: EntryKind::File { size: 0 },
            },
            skip.clone(),
            DirEntry {
                name: "e-in".into(),
                kind: EntryKind::File { size: 5 },
            },
            skip.clone(),
            skip.clone(),
        ];
        if list.len() == 8 {
            want.push(skip);
        }
        assert_eq!(list, want);
        assert_eq!(b.list("b.txt"), Err(BackendError::WrongKind));
        assert_eq!(b.list("nope"), Err(BackendError::NotFound));
        assert_eq!(b.list("a dir"), Ok(Vec::new()));
    }

    #[test]
    fn nothing_outside_the_root_is_touched() {
        let (tmp, root, outside) = setup();
        fs::write(root.join("in.txt"), b"inside").unwrap();
        symlink(&outside, root.join("out")).unwrap();
        symlink(outside.join("secret.txt"), root.join("secret")).unwrap();
        symlink(outside.join("new.txt"), root.join("dangling")).unwrap();
        let before_outside = snapshot(&outside);
        let before_tmp: Vec<_> = fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        let mut b = DirBackend::new(&root).unwrap().writable();
        let p = Err(BackendError::Protected);
        let f = Err(BackendError::Fail);
        // `..` anywhere.
        assert_eq!(b.open("../outside/secret.txt", OpenMode::Read).map(drop), f);
        assert_eq!(b.open("a/../../x", OpenMode::Create).map(drop), f);
        assert_eq!(b.list("..").map(drop), f);
        assert_eq!(b.mkdir("../made"), f);
        assert_eq!(b.rename("in.txt", "../moved"), f);
        // Absolute paths stay inside the root.
        assert_eq!(
            b.open(
                &outside.join("secret.txt").to_string_lossy(),
                OpenMode::Read
            )
            .map(drop),
            Err(BackendError::NotFound)
        );
        let abs_new = outside.join("abs.txt");
        assert_eq!(
            b.open(&abs_new.to_string_lossy(), OpenMode::Create)
                .map(drop),
            Err(BackendError::NotFound)
        );
        assert_eq!(read_all(&mut b, "/in.txt"), Ok(b"inside".to_vec()));
        // Links leading out: neither read, listed, written nor created through.
        assert_eq!(b.open("secret", OpenMode::Read).map(drop), p);
        assert_eq!(b.open("secret", OpenMode::Write).map(drop), p);
        assert_eq!(b.open("secret", OpenMode::Create).map(drop), p);
        assert_eq!(b.truncate("secret", 0), p);
        assert_eq!(b.open("out/secret.txt", OpenMode::Read).map(drop), p);
        assert_eq!(b.open("out/new.txt", OpenMode::Create).map(drop), p);
        assert_eq!(b.open("out/missing.txt", OpenMode::Read).map(drop), p);
        assert_eq!(b.list("out").map(drop), p);
        assert_eq!(b.mkdir("out/made"), p);
        assert_eq!(b.remove("out/secret.txt"), p);
        assert_eq!(b.rename("in.txt", "out/moved.txt"), p);
        assert_eq!(b.rename("out/secret.txt", "stolen.txt"), p);
        assert_eq!(
            b.open("dangling", OpenMode::Create).map(drop),
            Err(BackendError::NotFound)
        );
        assert_eq!(
            b.open("dangling", OpenMode::Write).map(drop),
            Err(BackendError::NotFound)
        );
        assert_eq!(b.mkdir("dangling"), Err(BackendError::Exists));
        assert_eq!(snapshot(&outside), before_outside);
        // Removing a link removes the link, not what it leads to.
        assert_eq!(b.remove("secret"), Ok(()));
        assert_eq!(b.remove("out"), Ok(()));
        assert_eq!(snapshot(&outside), before_outside);
        let after_tmp: Vec<_> = fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(after_tmp, before_tmp);
    }

    /// Moves messages between a client and a server until the client finishes.
    fn run(
        client: &mut FtpClient,
        server: &mut FtpServer<DirBackend>,
        now: &mut Instant,
    ) -> Result<FtpOutput, FtpError> {
        for _ in 0..100_000 {
            let mut moved = false;
            while let Some(out) = client.poll_transmit() {
                moved = true;
                server.handle_message(*now, GCS, &out.message);
            }
            while let Some(out) = server.poll_transmit() {
                moved = true;
                client.handle_message(*now, VEHICLE, &out.message);
            }
            while let Some(ev) = client.poll_event() {
                if let FtpEvent::Finished(r) = ev {
                    return r;
                }
            }
            if !moved {
                let next = [client.poll_timeout(), server.poll_timeout()]
                    .into_iter()
                    .flatten()
                    .min()
                    .expect("nothing moves and nothing is due");
                *now = (*now).max(next);
                client.handle_timeout(*now);
                server.handle_timeout(*now);
            }
            *now += Duration::from_micros(100);
        }
        panic!("did not finish");
    }

    #[test]
    fn client_against_a_directory_end_to_end() {
        let (_tmp, root, outside) = setup();
        symlink(&outside, root.join("out")).unwrap();
        let backend = DirBackend::new(&root).unwrap().writable();
        let mut server = FtpServer::new(VEHICLE, ServerConfig::default(), backend);
        let mut client = FtpClient::new(GCS, VEHICLE, ClientConfig::default());
        let mut now = Instant::from_secs(1);
        let data: Vec<u8> = (0..10_000usize).map(|i| (i * 7 + i / 251) as u8).collect();
        for dir in ["/logs", "/logs/day one"] {
            client.mkdir(now, dir).unwrap();
            assert_eq!(run(&mut client, &mut server, &mut now), Ok(FtpOutput::Done));
        }
        let path = "/logs/day one/flight log.bin";
        client.write(now, path, &data).unwrap();
        assert_eq!(run(&mut client, &mut server, &mut now), Ok(FtpOutput::Done));
        assert_eq!(
            fs::read(root.join("logs/day one/flight log.bin")).unwrap(),
            data
        );
        client.list(now, "/logs/day one").unwrap();
        assert_eq!(
            run(&mut client, &mut server, &mut now),
            Ok(FtpOutput::Listing(vec![DirEntry {
                name: "flight log.bin".into(),
                kind: EntryKind::File { size: 10_000 },
            }]))
        );
        client.read(now, path).unwrap();
        assert_eq!(
            run(&mut client, &mut server, &mut now),
            Ok(FtpOutput::Data(data.clone()))
        );
        client.crc32(now, path).unwrap();
        assert_eq!(
            run(&mut client, &mut server, &mut now),
            Ok(FtpOutput::Crc32(crc32(0, &data)))
        );
        // Refusals reach the client as NAKs.
        client.read(now, "/out/secret.txt").unwrap();
        assert_eq!(
            run(&mut client, &mut server, &mut now),
            Err(FtpError::Nak {
                code: NakCode::FileProtected,
                errno: None
            })
        );
        client.read(now, "/logs/../../outside/secret.txt").unwrap();
        assert_eq!(
            run(&mut client, &mut server, &mut now),
            Err(FtpError::Nak {
                code: NakCode::Fail,
                errno: None
            })
        );
        assert_eq!(server.open_sessions(), 0);
        assert_eq!(fs::read(outside.join("secret.txt")).unwrap(), b"secret");
    }
}
