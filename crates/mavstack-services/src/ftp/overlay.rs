//! Virtual files over a [`Backend`]: [`Overlay`] serves files whose contents a [`Provider`]
//! makes when they are opened (ArduPilot's `@PARAM/param.pck`, say), takes uploads to the
//! ones the provider accepts them for (whole, when the session closes), and passes every
//! other path to the backend under it.

use alloc::string::String;
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

    /// The size announced when `path` (one it provides) is opened with `contents`: their
    /// length by default. A provider may announce more, as ArduPilot announces an estimate
    /// for its packed parameters; reads end at the contents' real end (NAK EndOfFile).
    fn announced_size(&self, path: &str, contents: &[u8]) -> u64 {
        let _ = path;
        len_u64(contents.len())
    }

    /// The most bytes a client may write to `path` (one it provides) to upload it; `None`,
    /// the default, keeps the file read-only.
    fn upload_limit(&self, path: &str) -> Option<usize> {
        let _ = path;
        None
    }

    /// Takes what a client wrote to `path` (one with an [`upload_limit`](Self::upload_limit)),
    /// whole, when its session closes: completed, reset or timed out alike, so check that it
    /// is complete. Ignored by default.
    fn upload(&mut self, path: &str, contents: Vec<u8>) {
        let _ = (path, contents);
    }
}

/// An upload in progress: what a session has written to a virtual file so far.
#[derive(Debug)]
struct Upload {
    id: u64,
    path: String,
    data: Vec<u8>,
    limit: usize,
}

/// A file an [`Overlay`] opened: one of its backend's, or a virtual file's contents.
#[derive(Debug)]
pub enum OverlayHandle<H> {
    /// A file of the backend under it.
    Inner(H),
    /// A virtual file, as made when it was opened, and the size announced for it.
    Virtual(Vec<u8>, u64),
    /// A virtual file opened to upload it (its bytes are kept by the overlay).
    Upload(u64),
}

/// A [`Backend`] that serves a [`Provider`]'s virtual files (removing, renaming or
/// truncating one is refused with [`BackendError::Protected`], and so is opening it to
/// write unless the provider takes uploads of it), and every other path from the backend under it — or, with
/// none ([`Overlay::alone`]), an empty read-only root.
#[derive(Debug)]
pub struct Overlay<B, P> {
    inner: Option<B>,
    provider: P,
    /// Uploads of open sessions (as many as the server has sessions).
    uploads: Vec<Upload>,
    next_upload: u64,
}

impl<B: Backend, P: Provider> Overlay<B, P> {
    /// `provider`'s files over `inner`.
    #[must_use]
    pub const fn new(inner: B, provider: P) -> Self {
        Self {
            inner: Some(inner),
            provider,
            uploads: Vec::new(),
            next_upload: 0,
        }
    }

    /// `provider`'s files over an empty root where nothing can be created.
    #[must_use]
    pub const fn alone(provider: P) -> Self {
        Self {
            inner: None,
            provider,
            uploads: Vec::new(),
            next_upload: 0,
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

    fn upload_mut(&mut self, id: u64) -> Result<&mut Upload, BackendError> {
        self.uploads
            .iter_mut()
            .find(|u| u.id == id)
            .ok_or(BackendError::Fail)
    }
}

fn len_u64(n: usize) -> u64 {
    u64::try_from(n).unwrap_or(u64::MAX)
}

impl<B: Backend, P: Provider> Backend for Overlay<B, P> {
    type Handle = OverlayHandle<B::Handle>;

    fn open(&mut self, path: &str, mode: OpenMode) -> Result<Self::Handle, BackendError> {
        if self.provider.provides(path) {
            if mode == OpenMode::Read {
                let data = self.provider.contents(path)?;
                let size = self.provider.announced_size(path, &data);
                return Ok(OverlayHandle::Virtual(data, size));
            }
            let limit = self
                .provider
                .upload_limit(path)
                .ok_or(BackendError::Protected)?;
            let id = self.next_upload;
            self.next_upload += 1;
            self.uploads.push(Upload {
                id,
                path: String::from(path),
                data: Vec::new(),
                limit,
            });
            return Ok(OverlayHandle::Upload(id));
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
        match handle {
            OverlayHandle::Inner(h) => {
                if let Some(inner) = self.inner.as_mut() {
                    inner.close(h);
                }
            }
            OverlayHandle::Upload(id) => {
                if let Some(i) = self.uploads.iter().position(|u| u.id == id) {
                    let upload = self.uploads.swap_remove(i);
                    self.provider.upload(&upload.path, upload.data);
                }
            }
            OverlayHandle::Virtual(..) => {}
        }
    }

    fn size(&mut self, handle: &Self::Handle) -> Result<u64, BackendError> {
        match handle {
            OverlayHandle::Virtual(_, size) => Ok(*size),
            OverlayHandle::Upload(id) => Ok(len_u64(self.upload_mut(*id)?.data.len())),
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
            OverlayHandle::Virtual(data, _) => {
                let rest = usize::try_from(offset)
                    .ok()
                    .and_then(|o| data.get(o..))
                    .unwrap_or(&[]);
                let n = rest.len().min(buf.len());
                buf[..n].copy_from_slice(&rest[..n]);
                Ok(n)
            }
            OverlayHandle::Upload(_) => Err(BackendError::Fail),
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
            OverlayHandle::Virtual(..) => Err(BackendError::Protected),
            OverlayHandle::Upload(id) => {
                let upload = self.upload_mut(*id)?;
                let end = usize::try_from(offset)
                    .ok()
                    .and_then(|o| o.checked_add(data.len()))
                    .filter(|&end| end <= upload.limit)
                    .ok_or(BackendError::NoSpace)?;
                let start = end - data.len();
                if upload.data.len() < end {
                    upload.data.resize(end, 0);
                }
                upload.data[start..end].copy_from_slice(data);
                Ok(())
            }
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
        name: String::from(name),
        kind: EntryKind::File {
            size: len_u64(size),
        },
    }
}

/// A directory entry for a virtual directory.
#[must_use]
pub fn dir_entry(name: &str) -> DirEntry {
    DirEntry {
        name: String::from(name),
        kind: EntryKind::Directory,
    }
}

#[cfg(test)]
mod tests {
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

    /// `up` takes uploads of at most 8 bytes and keeps them.
    #[derive(Debug, Default)]
    struct Inbox(Vec<(String, Vec<u8>)>);

    impl Provider for Inbox {
        fn provides(&self, path: &str) -> bool {
            path == "up"
        }
        fn contents(&mut self, _path: &str) -> Result<Vec<u8>, BackendError> {
            Ok(Vec::new())
        }
        fn upload_limit(&self, _path: &str) -> Option<usize> {
            Some(8)
        }
        fn upload(&mut self, path: &str, contents: Vec<u8>) {
            self.0.push((String::from(path), contents));
        }
    }

    #[test]
    fn uploads_reach_the_provider_whole_when_the_session_closes() {
        let mut o: Overlay<MemoryBackend, Inbox> = Overlay::alone(Inbox::default());
        let a = o.open("up", OpenMode::Create).unwrap();
        let b = o.open("up", OpenMode::Write).unwrap();
        // Pieces out of order, and a retransmission.
        o.write(&a, 4, b"5678").unwrap();
        o.write(&a, 0, b"1234").unwrap();
        o.write(&a, 0, b"1234").unwrap();
        assert_eq!(o.size(&a), Ok(8));
        assert_eq!(o.write(&a, 5, b"9999"), Err(BackendError::NoSpace));
        assert_eq!(o.write(&a, u64::MAX, b"9"), Err(BackendError::NoSpace));
        o.write(&b, 0, b"x").unwrap();
        assert!(o.provider().0.is_empty(), "nothing before the close");
        o.close(a);
        o.close(b);
        assert_eq!(
            o.provider().0,
            [
                (String::from("up"), b"12345678".to_vec()),
                (String::from("up"), b"x".to_vec())
            ]
        );
        assert!(o.uploads.is_empty());
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
