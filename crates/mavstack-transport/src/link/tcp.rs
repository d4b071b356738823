//! TCP: the listener and its clients, a client connection.

use core::net::SocketAddr;
use core::time::Duration;
use std::io;

use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;

use crate::error::Reason;
use crate::protocol::{Framing, PeerAddr, PeerInfo};

use super::stream::{read_peer, spawn_writer};
use super::{LinkMsg, PeerIds};

/// A TCP listener on `addr` (with `SO_REUSEADDR`, so a restarted server can bind again while
/// old connections linger in TIME_WAIT).
pub(super) fn tcp_listener(addr: SocketAddr) -> io::Result<TcpListener> {
    use socket2::{Domain, Protocol as SockProtocol, Socket, Type};
    let socket = Socket::new(
        Domain::for_address(addr),
        Type::STREAM,
        Some(SockProtocol::TCP),
    )?;
    socket.set_reuse_address(true)?;
    socket.set_nonblocking(true)?;
    socket.bind(&addr.into())?;
    socket.listen(128)?;
    TcpListener::from_std(socket.into())
}

/// A TCP connection to `addr`, given up after `timeout`.
pub(super) async fn tcp_connect(addr: SocketAddr, timeout: Duration) -> Result<TcpStream, Reason> {
    match tokio::time::timeout(timeout, TcpStream::connect(addr)).await {
        Ok(Ok(stream)) => {
            if let Err(e) = stream.set_nodelay(true) {
                tracing::debug!("cannot set TCP_NODELAY: {e}");
            }
            Ok(stream)
        }
        Ok(Err(e)) => Err(Reason::from_io(&e)),
        Err(_) => Err(Reason::new(io::ErrorKind::TimedOut, "timed out")),
    }
}

/// Accepts TCP clients, each a peer, until the link closes.
pub(super) async fn serve_tcp(
    listener: TcpListener,
    ids: PeerIds,
    tx: mpsc::Sender<LinkMsg>,
    queue: usize,
) {
    // The link as its connection string names it, for the warnings.
    let link = listener
        .local_addr()
        .map_or_else(|_| "tcpin".to_owned(), |a| format!("tcpin:{a}"));
    loop {
        let accepted = tokio::select! {
            () = tx.closed() => return,
            r = listener.accept() => r,
        };
        match accepted {
            Ok((stream, addr)) => {
                if let Err(e) = stream.set_nodelay(true) {
                    tracing::debug!("cannot set TCP_NODELAY: {e}");
                }
                let info = PeerInfo {
                    id: ids.next(),
                    addr: PeerAddr::Tcp(addr),
                    framing: Framing::Stream,
                };
                let tx = tx.clone();
                tokio::spawn(async move {
                    let (reader, writer) = stream.into_split();
                    let what = info.addr.to_string();
                    let id = info.id;
                    let writer = spawn_writer(writer, what.clone(), queue);
                    let added = LinkMsg::PeerAdded {
                        info,
                        writer: Some(writer),
                    };
                    if tx.send(added).await.is_ok() {
                        read_peer(reader, id, &what, &tx).await;
                    }
                });
            }
            Err(e) => {
                // Out of file descriptors and the like: wait a little, then go on.
                tracing::warn!(link = %link, "{link}: tcp accept failed: {e}");
                tokio::select! {
                    () = tx.closed() => return,
                    () = tokio::time::sleep(Duration::from_millis(100)) => {}
                }
            }
        }
    }
}
