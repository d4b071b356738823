//! Two in-process links joined to each other ([`joined`]): a component with a node of its
//! own (a camera) beside another node (a simulated vehicle), as a companion computer is
//! beside its autopilot.

use mavstack_router::{LinkConfig, VersionMode};
use mavstack_transport::Link;

/// How many frames each way may wait for the other side.
const QUEUE: usize = 1024;

/// Two links, each the other's only peer: what a node sends on one arrives on the other.
/// Both speak MAVLink 2 from the first frame (the camera protocol's messages have ids over
/// 255). Give one to each node ([`NodeBuilder::opened_link`](crate::NodeBuilder::opened_link));
/// the frames are carried by a task that ends when either node closes its link.
///
/// # Panics
/// Outside a tokio runtime.
#[must_use]
pub fn joined(a: &str, b: &str) -> ((LinkConfig, Link), (LinkConfig, Link)) {
    let (link_a, mut peer_a) = Link::external(Some(b.to_owned()), QUEUE);
    let (link_b, mut peer_b) = Link::external(Some(a.to_owned()), QUEUE);
    tokio::spawn(async move {
        let (Some(from_a), Some(from_b)) = (peer_a.first(), peer_b.first()) else {
            return;
        };
        let (to_a, to_b) = (peer_a.sender(), peer_b.sender());
        loop {
            tokio::select! {
                frame = peer_a.recv() => match frame {
                    Some((_, bytes)) => {
                        if !to_b.deliver(from_b, bytes).await {
                            return;
                        }
                    }
                    None => return,
                },
                frame = peer_b.recv() => match frame {
                    Some((_, bytes)) => {
                        if !to_a.deliver(from_a, bytes).await {
                            return;
                        }
                    }
                    None => return,
                },
            }
        }
    });
    let config = |name: &str| {
        let mut c = LinkConfig::new(name);
        c.version = VersionMode::Mavlink2;
        c
    };
    ((config(b), link_a), (config(a), link_b))
}
