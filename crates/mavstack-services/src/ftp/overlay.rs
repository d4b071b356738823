//! Virtual files over a [`Backend`]: [`Overlay`] serves read-only files whose contents a
//! [`Provider`] makes when they are opened (ArduPilot's `@PARAM/param.pck`, say), and passes
//! every other path to the backend under it.

use alloc::vec::Vec;

use super::backend::{Backend, BackendError, OpenMode};
use super::payload::{DirEntry, EntryKind};

/// Makes the contents of virtual files.
pub trait Provider {
    /// Whether `path` (normalised, as [`Backend`] paths are) names one of its files.
    fn provides(&self, path: &str) -> bool;

    /// The contents of the file at `path` (one it [`provides`](Self::provides)), made now:
    /// called when a client opens the file (or asks its CRC32); the session reads this
    /// snapshot to its end.
    ///
    /// # Errors
    ///
    /// Whatever stops it (a bad query in the path, say): the client gets the NAK.
    fn contents(&mut self, path: &str) -> Result<Vec<u8>, BackendError>;

    /// Virtual entries to show in the listing of directory `dir` (after the backend's own).
    /// None by default.
    fn entries(&mut self, dir: &str) -> Vec<DirEntry> {
        let _ = dir;
        Vec::new()
    }
}

/// A file an [`Overlay`] opened: one of its backend's, or a virtual file's contents.
#[derive(Debug)]
pub enum OverlayHandle<H> {
    /// A file of the backend under it.
    Inner(H),
    /// A virtual file, as made when it was opened.
    Virtual(Vec<u8>),
}

/// A [`Backend`] that serves a [`Provider`]'s virtual files, read-only (opening one to
/// write, removing, renaming or truncating it is refused with
/// [`BackendError::Protected`]), and every other path from the backend under it — or, with
/// none ([`Overlay::alone`]), an empty read-only root.
#[derive(Debug)]
pub struct Overlay<B, P> {
    inner: Option<B>,
    provider: P,
}

impl<B: Backend, P: Provider> Overlay<B, P> {
    /// `provider`'s files over `inner`.
    #[must_use]
    pub const fn new(inner: B, provider: P) -> Self {
        Self {
            inner: Some(inner),
            provider,
        }
    }

    /// `provider`'s files over an empty root where nothing can be created.
    #[must_use]
    pub const fn alone(provider: P) -> Self {
        Self {
            inner: None,
            provider,
        }
    }

    /// The backend under it, if any.
    #[must_use]
    pub const fn inner(&self) -> Option<&B> {
        self.inner.as_ref()
    }

    /// The provider.
    #[must_use]
    pub const fn provider(&self) -> &P {
        &self.provider
    }

    /// The provider, mutably (to change what its files will contain).
    pub const fn provider_mut(&mut self) -> &mut P {
        &mut self.provider
    }

    fn inner_or(&mut self, missing: BackendError) -> Result<&mut B, BackendError> {
        self.inner.as_mut().ok_or(missing)
    }
}

fn len_u64(n: usize) -> u64 {
    u64::try_from(n).unwrap_or(u64::MAX)
}

impl<B: Backend, P: Provider> Backend for Overlay<B, P> {
    type Handle = OverlayHandle<B::Handle>;

    fn open(&mut self, path: &str, mode: OpenMode) -> Result<Self::Handle, BackendError> {
        if self.provider.provides(path) {
            if mode != OpenMode::Read {
                return Err(BackendError::Protected);
            }
            return self.provider.contents(path).map(OverlayHandle::Virtual);
        }
        let missing = match mode {
            OpenMode::Read => BackendError::NotFound,
            OpenMode::Write | OpenMode::Create => BackendError::Protected,
        };
        self.inner_or(missing)?
            .open(path, mode)
            .map(OverlayHandle::Inner)
    }

    fn close(&mut self, handle: Self::Handle) {
        if let (OverlayHandle::Inner(h), Some(inner)) = (handle, self.inner.as_mut()) {
            inner.close(h);
        }
    }

    fn size(&mut self, handle: &Self::Handle) -> Result<u64, BackendError> {
        match handle {
            OverlayHandle::Virtual(data) => Ok(len_u64(data.len())),
            OverlayHandle::Inner(h) => self.inner_or(BackendError::Fail)?.size(h),
        }
    }

    fn read(
        &mut self,
        handle: &Self::Handle,
        offset: u64,
        buf: &mut [u8],
    ) -> Result<usize, BackendError> {
        match handle {
            OverlayHandle::Virtual(data) => {
                let rest = usize::try_from(offset)
                    .ok()
                    .and_then(|o| data.get(o..))
                    .unwrap_or(&[]);
                let n = rest.len().min(buf.len());
                buf[..n].copy_from_slice(&rest[..n]);
                Ok(n)
            }
            OverlayHandle::Inner(h) => self.inner_or(BackendError::Fail)?.read(h, offset, buf),
        }
    }

    fn write(
        &mut self,
        handle: &Self::Handle,
        offset: u64,
        data: &[u8],
    ) -> Result<(), BackendError> {
        match handle {
            OverlayHandle::Virtual(_) => Err(BackendError::Protected),
            OverlayHandle::Inner(h) => self
                .inner_or(BackendError::Protected)?
                .write(h, offset, data),
        }
    }

    fn remove(&mut self, path: &str) -> Result<(), BackendError> {
        if self.provider.provides(path) {
            return Err(BackendError::Protected);
        }
        self.inner_or(BackendError::NotFound)?.remove(path)
    }

    fn mkdir(&mut self, path: &str) -> Result<(), BackendError> {
        self.inner_or(BackendError::Protected)?.mkdir(path)
    }

    fn rmdir(&mut self, path: &str) -> Result<(), BackendError> {
        self.inner_or(BackendError::NotFound)?.rmdir(path)
    }

    fn rename(&mut self, from: &str, to: &str) -> Result<(), BackendError> {
        if self.provider.provides(from) || self.provider.provides(to) {
            return Err(BackendError::Protected);
        }
        self.inner_or(BackendError::NotFound)?.rename(from, to)
    }

    fn truncate(&mut self, path: &str, len: u64) -> Result<(), BackendError> {
        if self.provider.provides(path) {
            return Err(BackendError::Protected);
        }
        self.inner_or(BackendError::NotFound)?.truncate(path, len)
    }

    fn list(&mut self, path: &str) -> Result<Vec<DirEntry>, BackendError> {
        let virtual_entries = self.provider.entries(path);
        let listed = match self.inner.as_mut() {
            Some(inner) => inner.list(path),
            None if path.is_empty() => Ok(Vec::new()),
            None => Err(BackendError::NotFound),
        };
        match listed {
            Ok(mut entries) => {
                // A virtual entry hides a real one of the same name.
                entries.retain(|e| virtual_entries.iter().all(|v| v.name != e.name));
                entries.extend(virtual_entries);
                Ok(entries)
            }
            Err(BackendError::NotFound) if !virtual_entries.is_empty() => Ok(virtual_entries),
            Err(e) => Err(e),
        }
    }
}

/// A directory entry for a virtual file of `size` bytes.
#[must_use]
pub fn file_entry(name: &str, size: usize) -> DirEntry {
    DirEntry {
        name: alloc::string::String::from(name),
        kind: EntryKind::File {
            size: len_u64(size),
        },
    }
}

/// A directory entry for a virtual directory.
#[must_use]
pub fn dir_entry(name: &str) -> DirEntry {
    DirEntry {
        name: alloc::string::String::from(name),
        kind: EntryKind::Directory,
    }
}

#[cfg(test)]
mod tests {
    use alloc::string::String;
    use alloc::vec;

    use super::super::MemoryBackend;
    use super::*;

    /// `v/n` holds the number of times it was opened.
    #[derive(Debug, Default)]
    struct Counter(u8);

    impl Provider for Counter {
        fn provides(&self, path: &str) -> bool {
            path == "v/n"
        }
        fn contents(&mut self, _path: &str) -> Result<Vec<u8>, BackendError> {
            self.0 += 1;
            Ok(vec![self.0])
        }
        fn entries(&mut self, dir: &str) -> Vec<DirEntry> {
            match dir {
                "" => vec![dir_entry("v")],
                "v" => vec![file_entry("n", 1)],
                _ => Vec::new(),
            }
        }
    }

    #[test]
    fn virtual_files_are_made_at_open_and_read_only() {
        let mut inner = MemoryBackend::new();
        assert!(inner.insert_file("real.txt", b"abc"));
        let mut o = Overlay::new(inner, Counter::default());
        let h = o.open("v/n", OpenMode::Read).unwrap();
        let mut buf = [0u8; 4];
        assert_eq!(o.read(&h, 0, &mut buf), Ok(1));
        assert_eq!(buf[0], 1);
        assert_eq!(o.read(&h, 1, &mut buf), Ok(0));
        assert_eq!(o.read(&h, u64::MAX, &mut buf), Ok(0));
        assert_eq!(o.size(&h), Ok(1));
        assert_eq!(o.write(&h, 0, b"x"), Err(BackendError::Protected));
        o.close(h);
        let h = o.open("v/n", OpenMode::Read).unwrap();
        assert_eq!(o.read(&h, 0, &mut buf), Ok(1));
        assert_eq!(buf[0], 2, "made again at the second open");
        for mode in [OpenMode::Write, OpenMode::Create] {
            assert!(matches!(o.open("v/n", mode), Err(BackendError::Protected)));
        }
        assert_eq!(o.remove("v/n"), Err(BackendError::Protected));
        assert_eq!(o.rename("v/n", "x"), Err(BackendError::Protected));
        assert_eq!(o.rename("real.txt", "v/n"), Err(BackendError::Protected));
        assert_eq!(o.truncate("v/n", 0), Err(BackendError::Protected));
        // Everything else is the backend's.
        let h = o.open("real.txt", OpenMode::Read).unwrap();
        assert_eq!(o.read(&h, 0, &mut buf), Ok(3));
        o.close(h);
        o.rename("real.txt", "moved.txt").unwrap();
        assert_eq!(o.inner().unwrap().file("moved.txt"), Some(&b"abc"[..]));
        let names = |l: Vec<DirEntry>| l.into_iter().map(|e| e.name).collect::<Vec<String>>();
        assert_eq!(names(o.list("").unwrap()), ["moved.txt", "v"]);
        assert_eq!(names(o.list("v").unwrap()), ["n"]);
        assert_eq!(o.list("w"), Err(BackendError::NotFound));
    }

    #[test]
    fn alone_it_is_an_empty_read_only_root() {
        let mut o: Overlay<MemoryBackend, Counter> = Overlay::alone(Counter::default());
        assert!(matches!(
            o.open("x", OpenMode::Read),
            Err(BackendError::NotFound)
        ));
        assert!(matches!(
            o.open("x", OpenMode::Create),
            Err(BackendError::Protected)
        ));
        assert_eq!(o.mkdir("d"), Err(BackendError::Protected));
        assert_eq!(o.list("").unwrap().len(), 1);
        assert!(o.open("v/n", OpenMode::Read).is_ok());
    }
}
