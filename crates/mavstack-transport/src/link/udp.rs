//! UDP: the socket the driver reads itself, batched, and the peers learned from it.

use core::net::SocketAddr;
use core::task::{Context, Poll};
use core::time::Duration;
use std::collections::HashMap;
use std::io;

use mavstack_core::time::Instant;

use crate::batch::{RECV_BATCH, RecvBatch, SendBatch};
use crate::clock;
use crate::connection::Options;
use crate::protocol::{Dest, Framing, Input, PeerAddr, PeerId, PeerInfo};
use crate::udp_io::UdpIo;

use super::admission::{Admission, IDLE_AFTER};
use super::{BATCH, LinkStats, PeerIds, PeerTable};

/// A UDP socket bound to `addr` with big buffers.
pub(super) fn udp_socket(
    addr: SocketAddr,
    broadcast: bool,
    options: &Options,
) -> io::Result<UdpIo> {
    use socket2::{Domain, Protocol as SockProtocol, Socket, Type};
    let socket = Socket::new(
        Domain::for_address(addr),
        Type::DGRAM,
        Some(SockProtocol::UDP),
    )?;
    if broadcast {
        socket.set_broadcast(true)?;
    }
    // Best effort: the kernel caps the sizes (net.core.rmem_max / wmem_max).
    if let Err(e) = socket.set_recv_buffer_size(options.socket_buffer) {
        tracing::debug!("cannot set SO_RCVBUF: {e}");
    }
    if let Err(e) = socket.set_send_buffer_size(options.socket_buffer) {
        tracing::debug!("cannot set SO_SNDBUF: {e}");
    }
    socket.set_nonblocking(true)?;
    socket.bind(&addr.into())?;
    UdpIo::new(socket.into())
}

#[derive(Debug)]
pub(super) struct Learned {
    pub(super) addr: SocketAddr,
    pub(super) last_seen: Instant,
}

#[derive(Debug)]
pub(super) struct Udp {
    pub(super) socket: UdpIo,
    pub(super) rx: RecvBatch,
    pub(super) tx: SendBatch,
    /// Pack frames for one peer into datagrams up to this many bytes (0: one per datagram).
    pub(super) pack: usize,
    pub(super) peers: UdpPeers,
}

/// A map looked up per datagram: foldhash (seeded per process) instead of SipHash, a tenth
/// of the cost for a socket address.
pub(super) type FastMap<K, V> = HashMap<K, V, foldhash::fast::RandomState>;

/// The peers of one UDP socket.
#[derive(Debug)]
pub(super) struct UdpPeers {
    /// `udpout`/`udpbcast`: the fixed destination, a peer that never expires.
    pub(super) target: Option<(PeerId, SocketAddr)>,
    pub(super) by_addr: FastMap<SocketAddr, PeerId>,
    pub(super) learned: FastMap<PeerId, Learned>,
    pub(super) peer_timeout: Duration,
    pub(super) next_expiry: Option<Instant>,
    pub(super) ids: PeerIds,
    /// Who may become a peer, and how many.
    pub(super) admission: Admission,
}

impl Udp {
    pub(super) fn new(
        socket: UdpIo,
        target: Option<(PeerId, SocketAddr)>,
        ids: PeerIds,
        options: &Options,
    ) -> Self {
        Self {
            socket,
            rx: RecvBatch::new(),
            tx: SendBatch::default(),
            pack: 0,
            peers: UdpPeers {
                target,
                by_addr: FastMap::default(),
                learned: FastMap::default(),
                peer_timeout: options.peer_timeout,
                next_expiry: None,
                ids,
                admission: Admission::default(),
            },
        }
    }

    pub(super) fn poll_ready(&self, cx: &mut Context<'_>) -> Poll<()> {
        // An error (ICMP and the like) shows as readiness too: the receive reports it.
        self.socket.poll_read_ready(cx)
    }

    pub(super) fn dispatch<I: Input>(
        &mut self,
        input: &mut I,
        stats: &mut LinkStats,
        table: &PeerTable,
    ) -> usize {
        // Drain what is waiting, a batch per system call, before going back to the loop; a
        // datagram that came alone is handed on at once, and the next read waits for the
        // next call (after the caller has forwarded this one).
        let mut delivered = 0;
        for _ in 0..BATCH.div_ceil(RECV_BATCH) {
            let got = match self.rx.recv(&mut self.socket) {
                Ok(got) => got,
                Err(e) => {
                    stats.rx_errors += 1;
                    tracing::debug!("udp receive error: {e}");
                    return delivered;
                }
            };
            // One reading of the clock for the datagrams of one receive.
            let now = clock::now();
            for i in 0..got.count {
                if let Some((bytes, from)) = self.rx.get(i) {
                    self.peers.deliver(now, input, bytes, from, stats, table);
                }
            }
            delivered += got.count;
            stats.rx_errors += core::mem::take(&mut self.rx.truncated);
            if !got.more || got.count == 1 {
                return delivered;
            }
        }
        delivered
    }

    /// Queues a datagram for the next [`Udp::flush`] (flushing at once when the batch is
    /// full).
    pub(super) fn queue(&mut self, dest: Dest, data: &[u8], stats: &mut LinkStats) {
        let mut full = false;
        let mut none = true;
        self.peers.each_dest(dest, |addr| {
            none = false;
            full |= self.tx.push(data, addr, self.pack);
        });
        if none {
            stats.tx_dropped += 1;
        }
        if full {
            self.flush(stats);
        }
    }

    pub(super) fn flush(&mut self, stats: &mut LinkStats) {
        if self.tx.is_empty() {
            return;
        }
        let sent = self.tx.flush(&self.socket);
        stats.tx_chunks += sent.datagrams;
        stats.tx_bytes += sent.bytes;
        stats.tx_dropped += sent.dropped;
        stats.tx_errors += sent.errors;
    }

    pub(super) async fn transmit(&mut self, dest: Dest, data: &[u8], stats: &mut LinkStats) {
        let mut addrs = Vec::new();
        self.peers.each_dest(dest, |a| addrs.push(a));
        if addrs.is_empty() {
            stats.tx_dropped += 1;
        }
        for addr in addrs {
            send_to(&self.socket, data, addr, stats).await;
        }
    }
}

impl UdpPeers {
    pub(super) fn deliver<I: Input>(
        &mut self,
        now: Instant,
        input: &mut I,
        data: &[u8],
        from: SocketAddr,
        stats: &mut LinkStats,
        table: &PeerTable,
    ) {
        stats.rx_chunks += 1;
        stats.rx_bytes += data.len() as u64;
        let id = match self.target {
            Some((id, addr)) if addr == from => id,
            _ => {
                if let Some(&id) = self.by_addr.get(&from) {
                    if let Some(peer) = self.learned.get_mut(&id) {
                        peer.last_seen = now;
                    }
                    id
                } else {
                    // A new source: a peer only with a MAVLink frame, and room for it.
                    if !self.admission.holds_frame(data) {
                        stats.rx_unadmitted += 1;
                        return;
                    }
                    if self.learned.len() >= self.admission.max_peers
                        && !self.make_room(now, input, stats, table)
                    {
                        stats.peers_refused += 1;
                        self.admission.refused(now, stats.peers_refused);
                        return;
                    }
                    let id = self.ids.next();
                    let info = PeerInfo {
                        id,
                        addr: PeerAddr::Udp(from),
                        framing: Framing::Datagram,
                    };
                    tracing::debug!("udp peer {from} appeared as {id}");
                    self.by_addr.insert(from, id);
                    self.learned.insert(
                        id,
                        Learned {
                            addr: from,
                            last_seen: now,
                        },
                    );
                    self.next_expiry.get_or_insert(now + self.peer_timeout);
                    table.add(info.clone());
                    stats.peers_added += 1;
                    input.handle_peer_added(now, &info);
                    id
                }
            }
        };
        input.handle_input(now, id, data);
    }

    /// At `max_peers`: removes the peer quiet the longest if it has been quiet for
    /// [`IDLE_AFTER`]. Whether there is room now.
    fn make_room<I: Input>(
        &mut self,
        now: Instant,
        input: &mut I,
        stats: &mut LinkStats,
        table: &PeerTable,
    ) -> bool {
        let oldest = self
            .learned
            .iter()
            .min_by_key(|(_, p)| p.last_seen)
            .filter(|(_, p)| now - p.last_seen >= IDLE_AFTER)
            .map(|(&id, _)| id);
        let Some(id) = oldest else {
            return false;
        };
        if let Some(peer) = self.learned.remove(&id) {
            tracing::debug!("udp peer {} ({id}) makes room for a new one", peer.addr);
            self.by_addr.remove(&peer.addr);
            table.remove(id);
            stats.peers_removed += 1;
            stats.peers_evicted += 1;
            input.handle_peer_removed(now, id);
        }
        true
    }

    pub(super) fn expire<I: Input>(
        &mut self,
        input: &mut I,
        stats: &mut LinkStats,
        table: &PeerTable,
    ) {
        let now = clock::now();
        let timeout = self.peer_timeout;
        let gone: Vec<PeerId> = self
            .learned
            .iter()
            .filter(|(_, p)| now - p.last_seen >= timeout)
            .map(|(&id, _)| id)
            .collect();
        for id in gone {
            if let Some(peer) = self.learned.remove(&id) {
                tracing::debug!("udp peer {} ({id}) went quiet", peer.addr);
                self.by_addr.remove(&peer.addr);
                table.remove(id);
                stats.peers_removed += 1;
                input.handle_peer_removed(now, id);
            }
        }
        self.next_expiry = self.learned.values().map(|p| p.last_seen + timeout).min();
    }

    /// Calls `f` with every address `dest` names.
    pub(super) fn each_dest(&self, dest: Dest, mut f: impl FnMut(SocketAddr)) {
        match dest {
            Dest::Peer(id) => {
                let addr = match self.target {
                    Some((t, addr)) if t == id => Some(addr),
                    _ => self.learned.get(&id).map(|p| p.addr),
                };
                if let Some(addr) = addr {
                    f(addr);
                }
            }
            Dest::All | Dest::AllExcept(_) => {
                let except = match dest {
                    Dest::AllExcept(id) => Some(id),
                    _ => None,
                };
                if let Some((id, addr)) = self.target {
                    if except != Some(id) {
                        f(addr);
                    }
                    return;
                }
                for (&id, peer) in &self.learned {
                    if except != Some(id) {
                        f(peer.addr);
                    }
                }
            }
        }
    }
}

pub(super) async fn send_to(socket: &UdpIo, data: &[u8], addr: SocketAddr, stats: &mut LinkStats) {
    match socket.send_to(data, addr).await {
        Ok(n) => {
            stats.tx_chunks += 1;
            stats.tx_bytes += n as u64;
        }
        Err(e) => {
            stats.tx_errors += 1;
            tracing::debug!("udp send to {addr} failed: {e}");
        }
    }
}
