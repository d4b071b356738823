//! Batched UDP I/O: many datagrams per system call (`recvmmsg`, `sendmmsg` on Linux, through
//! `nix`; one datagram per call elsewhere). The hot path of a router: at 100 k frames/s a
//! system call per datagram costs more than everything else together.

use core::net::SocketAddr;
use std::io;

use crate::udp_io::UdpIo;

/// Datagrams taken per receive call.
pub(crate) const RECV_BATCH: usize = 32;
/// Bytes per receive slot: a datagram longer than this is cut and counted as an error
/// (MAVLink datagrams hold a few frames of at most 280 bytes).
pub(crate) const RECV_SLOT: usize = 8192;
/// Bytes from one slot's start to the next: a slot and a cache line more, so that the slots'
/// first lines (where a small datagram lies) fall in different cache sets. At a stride of
/// exactly 8 KiB they all compete for the ways of one set.
const SLOT_STRIDE: usize = RECV_SLOT + 64;
/// Datagrams per send call.
pub(crate) const SEND_BATCH: usize = 64;
/// The largest datagram frames are packed into: an Ethernet MTU less the IP and UDP headers.
pub(crate) const PACK_LIMIT: usize = 1472;

/// Datagrams asked for while they come one at a time: the second slot only tells whether
/// the socket is drained, which saves the read that would find it empty.
const PAIR: usize = 2;

/// Whether a receive takes several datagrams per call (and so knows, when it gets fewer
/// than it asked for, that the socket is drained).
const BATCHED: bool = cfg!(target_os = "linux");

/// Receive buffers for one socket.
///
/// Two modes: while datagrams come one at a time (a wake-up each), a read asks for two, so
/// that the one that came goes on at once and the socket is known to be drained without
/// another system call; once a read finds two waiting, batches of [`RECV_BATCH`] are taken,
/// until a batch finds at most one.
#[derive(Debug)]
pub(crate) struct RecvBatch {
    buf: Vec<u8>,
    /// Per datagram taken: its slot, length and sender.
    got: Vec<(usize, usize, SocketAddr)>,
    /// Datagrams cut because they were longer than a slot.
    pub(crate) truncated: u64,
    /// Batch mode (see above).
    busy: bool,
    /// Batches whatever the reads find: the driver says the stream is steady (see
    /// [`crate::Link::set_bulk_reads`]).
    pub(crate) bulk: bool,
}

/// What one [`RecvBatch::recv`] found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Received {
    /// Datagrams taken.
    pub(crate) count: usize,
    /// More may be waiting (the socket is still marked readable): read again, after
    /// forwarding these.
    pub(crate) more: bool,
}

impl RecvBatch {
    pub(crate) fn new() -> Self {
        Self {
            buf: vec![0; RECV_BATCH * SLOT_STRIDE],
            got: Vec::with_capacity(RECV_BATCH),
            truncated: 0,
            busy: false,
            bulk: false,
        }
    }

    /// Receives what is waiting without blocking: up to two datagrams, or up to
    /// [`RECV_BATCH`] in batch mode.
    ///
    /// # Errors
    /// A receive error other than "would block".
    pub(crate) fn recv(&mut self, socket: &mut UdpIo) -> io::Result<Received> {
        self.got.clear();
        // A socket under a level-triggered poll of the caller's is read one datagram at a
        // time while they come one at a time: the poll reports it again if another waits.
        let level = socket.level_triggered();
        let want = if self.busy || self.bulk {
            RECV_BATCH
        } else if level {
            1
        } else {
            PAIR
        };
        let count = match socket.try_read(|s| self.recv_now(s, want)) {
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => 0,
            Err(e) => return Err(e),
        };
        let drained = (BATCHED && count < want) || (level && want == 1);
        if drained && count > 0 {
            // Fewer than asked for: the queue was empty when the call returned. Say so to
            // the runtime now rather than with another system call (a datagram that
            // arrived meanwhile raised readiness again: the runtime's ticks see to that).
            // A level-triggered poll reports the socket again if one more waits.
            socket.drained();
        }
        if !level {
            self.busy = if self.busy { count > 1 } else { count == PAIR };
        }
        Ok(Received {
            count,
            more: count > 0 && !drained,
        })
    }

    /// Datagram `i` of the last receive: its bytes and sender.
    pub(crate) fn get(&self, i: usize) -> Option<(&[u8], SocketAddr)> {
        let &(slot, len, from) = self.got.get(i)?;
        let start = slot * SLOT_STRIDE;
        Some((&self.buf[start..start + len], from))
    }

    /// One `recvmmsg` for up to `want` (two or [`RECV_BATCH`]) datagrams (headers kept per
    /// thread: no allocation).
    #[cfg(target_os = "linux")]
    fn recv_now(&mut self, socket: &std::net::UdpSocket, want: usize) -> io::Result<usize> {
        if want == 1 {
            self.recv_one(socket)
        } else if want <= PAIR {
            self.recv_slots::<PAIR>(socket)
        } else {
            self.recv_slots::<RECV_BATCH>(socket)
        }
    }

    /// One `recvmmsg` into the first `N` slots.
    #[cfg(target_os = "linux")]
    fn recv_slots<const N: usize>(&mut self, socket: &std::net::UdpSocket) -> io::Result<usize> {
        use core::cell::RefCell;
        use std::io::IoSliceMut;
        use std::os::fd::AsRawFd as _;

        use nix::sys::socket::{MsgFlags, MultiHeaders, SockaddrStorage, recvmmsg};

        thread_local! {
            static HEADERS: RefCell<MultiHeaders<SockaddrStorage>> =
                RefCell::new(MultiHeaders::preallocate(RECV_BATCH, None));
        }
        let (buf, got, truncated) = (&mut self.buf, &mut self.got, &mut self.truncated);
        HEADERS.with(|headers| {
            let mut headers = headers.borrow_mut();
            let mut chunks = buf
                .chunks_exact_mut(SLOT_STRIDE)
                .map(|c| &mut c[..RECV_SLOT]);
            let mut slices: [[IoSliceMut<'_>; 1]; N] =
                core::array::from_fn(|_| [IoSliceMut::new(chunks.next().unwrap_or(&mut []))]);
            let results = recvmmsg(
                socket.as_raw_fd(),
                &mut headers,
                slices.iter_mut(),
                MsgFlags::MSG_DONTWAIT,
                None,
            )
            .map_err(io::Error::from)?;
            for (slot, r) in results.enumerate() {
                if r.flags.contains(MsgFlags::MSG_TRUNC) {
                    *truncated += 1;
                }
                let from = r.address.and_then(|a| to_std(&a));
                // A datagram without a usable sender (not IP) cannot be answered: skipped
                // (the next ones keep their own slots).
                if let Some(from) = from {
                    got.push((slot, r.bytes.min(RECV_SLOT), from));
                }
            }
            Ok(got.len())
        })
    }

    /// One datagram per call off Linux.
    #[cfg(not(target_os = "linux"))]
    fn recv_now(&mut self, socket: &std::net::UdpSocket, _want: usize) -> io::Result<usize> {
        self.recv_one(socket)
    }

    /// One `recvfrom` into the first slot.
    fn recv_one(&mut self, socket: &std::net::UdpSocket) -> io::Result<usize> {
        let (len, from) = socket.recv_from(&mut self.buf[..RECV_SLOT])?;
        if len >= RECV_SLOT {
            // Cut (or exactly a slot long, which no MAVLink datagram is).
            self.truncated += 1;
        }
        self.got.push((0, len.min(RECV_SLOT), from));
        Ok(1)
    }
}

#[cfg(target_os = "linux")]
fn to_std(addr: &nix::sys::socket::SockaddrStorage) -> Option<SocketAddr> {
    if let Some(v4) = addr.as_sockaddr_in() {
        return Some(SocketAddr::V4((*v4).into()));
    }
    addr.as_sockaddr_in6()
        .map(|v6| SocketAddr::V6((*v6).into()))
}

/// Datagrams waiting to be sent on one socket.
#[derive(Debug, Default)]
pub(crate) struct SendBatch {
    bytes: Vec<u8>,
    items: Vec<(usize, usize, SocketAddr)>,
}

/// What one flush did.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Sent {
    pub(crate) datagrams: u64,
    pub(crate) bytes: u64,
    /// Datagrams dropped: the socket's buffer was full, or a send error.
    pub(crate) dropped: u64,
    pub(crate) errors: u64,
}

impl SendBatch {
    /// Queues `data` for `to`; true when the batch is full and should be flushed. With
    /// `pack` above 0, `data` joins the previous datagram when that one goes to the same
    /// address and both fit in `pack` bytes (MAVLink frames delimit themselves, so several
    /// can share a datagram; only what is already waiting is packed, so no frame waits).
    pub(crate) fn push(&mut self, data: &[u8], to: SocketAddr, pack: usize) -> bool {
        if let Some(last) = self.items.last_mut()
            && last.2 == to
            && last.1 + data.len() <= pack
        {
            self.bytes.extend_from_slice(data);
            last.1 += data.len();
            return false;
        }
        let start = self.bytes.len();
        self.bytes.extend_from_slice(data);
        self.items.push((start, data.len(), to));
        self.items.len() >= SEND_BATCH
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// Sends everything queued without blocking. What the socket refuses (its buffer is
    /// full) is dropped and counted: a router must not stall every link for one.
    pub(crate) fn flush(&mut self, socket: &UdpIo) -> Sent {
        let mut sent = Sent::default();
        let mut from = 0;
        while from < self.items.len() {
            let result = if self.items.len() - from == 1 {
                // One datagram: a plain sendto costs less than setting up a sendmmsg.
                let (start, len, to) = self.items[from];
                socket
                    .try_send_to(&self.bytes[start..start + len], to)
                    .map(|_| 1)
            } else {
                self.send_now(socket.get_ref(), from)
            };
            match result {
                Ok(n) => {
                    for &(_, len, _) in &self.items[from..from + n] {
                        sent.datagrams += 1;
                        sent.bytes += len as u64;
                    }
                    from += n.max(1);
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    sent.dropped += (self.items.len() - from) as u64;
                    break;
                }
                Err(e) => {
                    // One bad destination (ICMP unreachable, no route): skip that datagram.
                    tracing::debug!("udp send to {} failed: {e}", self.items[from].2);
                    sent.errors += 1;
                    sent.dropped += 1;
                    from += 1;
                }
            }
        }
        self.items.clear();
        self.bytes.clear();
        sent
    }

    #[cfg(target_os = "linux")]
    fn send_now(&self, socket: &std::net::UdpSocket, from: usize) -> io::Result<usize> {
        use std::io::IoSlice;
        use std::os::fd::AsRawFd as _;

        use nix::sys::socket::{ControlMessage, MsgFlags, MultiHeaders, SockaddrStorage, sendmmsg};

        let items = &self.items[from..(from + SEND_BATCH).min(self.items.len())];
        let mut headers = MultiHeaders::<SockaddrStorage>::preallocate(items.len(), None);
        let slices: Vec<[IoSlice<'_>; 1]> = items
            .iter()
            .map(|&(start, len, _)| [IoSlice::new(&self.bytes[start..start + len])])
            .collect();
        let addrs: Vec<Option<SockaddrStorage>> =
            items.iter().map(|&(_, _, to)| Some(to.into())).collect();
        let cmsgs: [ControlMessage<'_>; 0] = [];
        let results = sendmmsg(
            socket.as_raw_fd(),
            &mut headers,
            slices.iter(),
            &addrs,
            cmsgs,
            MsgFlags::MSG_DONTWAIT,
        )
        .map_err(io::Error::from)?;
        Ok(results.count())
    }

    #[cfg(not(target_os = "linux"))]
    fn send_now(&self, socket: &std::net::UdpSocket, from: usize) -> io::Result<usize> {
        let (start, len, to) = self.items[from];
        socket.send_to(&self.bytes[start..start + len], to)?;
        Ok(1)
    }
}
