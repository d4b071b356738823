//! [`GimbalDiscovery`]: the gimbal managers of one system, found by asking for
//! GIMBAL_MANAGER_INFORMATION.

use alloc::string::String;
use alloc::vec::Vec;

use mavstack_core::Message as _;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{GimbalDeviceInformation, GimbalManagerInformation, MavMessage};

use super::{GimbalInfo, MAX_NON_MAVLINK_DEVICE};
pub use crate::search::DiscoveryConfig;
use crate::search::Search;
use crate::{Address, Outgoing, Service};

/// A search for the gimbal managers of one system: MAV_CMD_REQUEST_MESSAGE(GIMBAL_MANAGER_INFORMATION)
/// to the whole system (component 0) and to each component known to be there, again every
/// [`DiscoveryConfig::ask_every`] until one answers; each manager found is then asked for
/// its device's GIMBAL_DEVICE_INFORMATION (vendor and model; the manager answers for a
/// device without a component of its own). It ends [`DiscoveryConfig::settle`] after the
/// last manager found, or at [`DiscoveryConfig::limit`] with none. A [`Service`]: drive it
/// and read [`poll_result`](Self::poll_result).
///
/// COMMAND_ACKs are not awaited: a request to component 0 is answered by each component
/// that has something to say (and refused by the others), which is the point.
#[derive(Clone, Debug)]
pub struct GimbalDiscovery {
    search: Search,
    found: Vec<GimbalInfo>,
}

impl GimbalDiscovery {
    /// Starts looking for the managers of `system`, asking its `components` (those heard,
    /// the autopilot at least) besides the whole system.
    #[must_use]
    pub fn new(now: Instant, system: u8, components: &[u8], config: DiscoveryConfig) -> Self {
        let mut d = Self {
            search: Search::new(now, system, components, config),
            found: Vec::new(),
        };
        d.handle_timeout(now);
        d
    }

    /// The managers found, in the order they answered, once the search has ended; given
    /// once.
    pub fn poll_result(&mut self) -> Option<Vec<GimbalInfo>> {
        self.search.take().then(|| core::mem::take(&mut self.found))
    }
}

/// A NUL-terminated text field as a string (invalid UTF-8 replaced).
pub(crate) fn text(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

impl Service for GimbalDiscovery {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        if self.search.done() || from.system != self.search.system {
            return false;
        }
        match message {
            MavMessage::GimbalManagerInformation(info) => {
                let known = self
                    .found
                    .iter()
                    .any(|g| g.manager == from && g.device_id == info.gimbal_device_id);
                if !known {
                    self.found.push(GimbalInfo::from_information(from, info));
                    self.search.found(now);
                    self.search.next_ask = None;
                    // The device's own component, or the manager on its behalf.
                    let asked = if info.gimbal_device_id > MAX_NON_MAVLINK_DEVICE {
                        info.gimbal_device_id
                    } else {
                        from.component
                    };
                    self.search.request(asked, GimbalDeviceInformation::ID);
                }
                true
            }
            MavMessage::GimbalDeviceInformation(dev) => {
                let device = if dev.gimbal_device_id == 0 {
                    from.component
                } else {
                    dev.gimbal_device_id
                };
                let Some(g) = self.found.iter_mut().find(|g| {
                    g.device_id == device
                        && (g.device_id > MAX_NON_MAVLINK_DEVICE
                            || g.manager.component == from.component)
                }) else {
                    return false;
                };
                g.vendor = text(&dev.vendor_name);
                g.model = text(&dev.model_name);
                g.custom_name = text(&dev.custom_name);
                true
            }
            _ => false,
        }
    }

    fn handle_timeout(&mut self, now: Instant) {
        if self.search.tick(now) {
            self.search.request(0, GimbalManagerInformation::ID);
            for c in self.search.components.clone() {
                self.search.request(c, GimbalManagerInformation::ID);
            }
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.search.poll_transmit()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.search.poll_timeout()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavstack_dialects::common::GimbalManagerCapFlags;

    fn requests(d: &mut GimbalDiscovery) -> Vec<(u8, u32)> {
        core::iter::from_fn(|| d.poll_transmit())
            .map(|o| match o.message {
                MavMessage::CommandLong(c) => (c.target_component, c.param1 as u32),
                m => panic!("{m:?}"),
            })
            .collect()
    }

    #[test]
    fn finds_two_managers_and_their_devices() {
        let t = |ms| Instant::from_millis(ms);
        let mut d = GimbalDiscovery::new(t(0), 1, &[1, 154, 1], DiscoveryConfig::default());
        assert_eq!(requests(&mut d), [(0, 280), (1, 280), (154, 280)]);
        // Nobody answers: asked again.
        d.handle_timeout(t(500));
        assert_eq!(requests(&mut d).len(), 3);
        let info = |device| {
            MavMessage::GimbalManagerInformation(GimbalManagerInformation {
                gimbal_device_id: device,
                cap_flags: GimbalManagerCapFlags::HAS_PITCH_AXIS,
                ..Default::default()
            })
        };
        assert!(d.handle_message(t(600), Address::new(1, 1), &info(1)));
        assert!(d.handle_message(t(610), Address::new(1, 154), &info(155)));
        // A copy of an answer, and another system's, change nothing.
        assert!(d.handle_message(t(620), Address::new(1, 1), &info(1)));
        assert!(!d.handle_message(t(620), Address::new(2, 1), &info(1)));
        assert_eq!(requests(&mut d), [(1, 283), (155, 283)]);
        let dev = MavMessage::GimbalDeviceInformation(GimbalDeviceInformation {
            vendor_name: *b"Acme\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0",
            ..Default::default()
        });
        assert!(d.handle_message(t(650), Address::new(1, 155), &dev));
        d.handle_timeout(t(1000));
        assert_eq!(d.poll_result(), None);
        assert_eq!(d.poll_timeout(), Some(t(1310)));
        d.handle_timeout(t(1310));
        let found = d.poll_result().unwrap();
        assert_eq!(found.len(), 2);
        assert_eq!(
            (found[0].manager, found[0].device_id),
            (Address::new(1, 1), 1)
        );
        assert_eq!(
            (found[1].manager, found[1].device_id),
            (Address::new(1, 154), 155)
        );
        assert_eq!(found[1].vendor, "Acme");
        assert_eq!(d.poll_result(), None);
    }

    #[test]
    fn none_found_at_the_limit() {
        let mut d = GimbalDiscovery::new(Instant::ZERO, 1, &[1], DiscoveryConfig::default());
        let mut t = Instant::ZERO;
        while let Some(next) = d.poll_timeout() {
            t = next;
            d.handle_timeout(t);
        }
        assert_eq!(t, Instant::from_secs(3));
        assert_eq!(d.poll_result(), Some(Vec::new()));
    }
}
