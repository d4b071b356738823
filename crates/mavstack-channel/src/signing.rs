//! Signing on one link: keys, outgoing timestamps, the replay table, the unsigned allow-list.
//!
//! The stateless primitives (SHA-256 signature, constant-time compare, zeroized key) live in
//! [`mavstack_core::signing`]; this module keeps the per-link state around them:
//!
//! - **Keys**: up to [`MAX_KEYS`]. Outgoing frames are signed with the first (primary) key;
//!   incoming signatures are checked against every key (key rotation).
//! - **Outgoing timestamps** (10 µs units since 2015-01-01 UTC) never go backwards: each frame
//!   gets `max(clock-derived, last + 1)`, where "last" also rises to the timestamp of every
//!   correctly signed frame received. The clock comes from the channel's `now` through
//!   [`WallClock`].
//! - **Persistence** by reservation: before the channel uses a timestamp at or above the
//!   value last handed out for storage, it asks the caller (with
//!   [`Event::PersistTimestamp`](crate::Event::PersistTimestamp)) to store `timestamp +
//!   persist_margin`. A restart that passes the stored value back as
//!   [`SigningConfig::initial_timestamp`] therefore never reuses a timestamp, even without a
//!   clock. With the default margin of one minute, the caller stores at most once per
//!   6 000 000 frames and at most once a minute of wall-clock time.
//! - **Replay protection**: one entry per stream (sysid, compid, link id), up to
//!   [`MAX_STREAMS`]. The signature is verified **before** the table is read or written, so a
//!   forged frame cannot move a stream's timestamp (the pymavlink lockout).
//! - **Unsigned allow-list**: message ids accepted without a signature (RADIO_STATUS by
//!   default, which SiK radios inject), up to [`MAX_UNSIGNED_IDS`].

use mavstack_core::message::Message;
use mavstack_core::signing::{self, MAX_TIMESTAMP, SecretKey};
use mavstack_core::time::Instant;
use mavstack_core::wire::Frame;
use mavstack_dialects::common::RadioStatus;

use crate::event::RejectReason;

/// How many keys a link can hold.
pub const MAX_KEYS: usize = 4;
/// How many message ids the unsigned allow-list can hold.
pub const MAX_UNSIGNED_IDS: usize = 8;
/// How many signing streams (sysid, compid, link id) a link tracks. A frame of a new stream
/// when the table is full is rejected ([`RejectReason::StreamTableFull`]), as the C library
/// does: forgetting a stream would let its recent frames be replayed.
pub const MAX_STREAMS: usize = 32;
/// How far behind the link's current timestamp the first frame of a new stream may be: one
/// minute, in 10 µs units (the C library's `MAVLINK_SIGNING_TIMESTAMP_LIMIT`).
pub const NEW_STREAM_WINDOW: u64 = 6_000_000;
/// The default [`SigningConfig::persist_margin`]: one minute, in 10 µs units.
pub const DEFAULT_PERSIST_MARGIN: u64 = 6_000_000;

/// Where the wall clock for outgoing signing timestamps comes from.
///
/// The channel never reads a clock. Signing timestamps count 10 µs units since
/// 2015-01-01 UTC, so the channel derives them from the `now` it is given, and needs to know
/// how `now` relates to the Unix epoch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum WallClock {
    /// `now.as_micros()` counts microseconds since the Unix epoch. This holds for the
    /// instants of `mavstack-transport` (its clock is anchored to the Unix epoch at start-up)
    /// and of the simulation tests.
    #[default]
    InstantIsUnix,
    /// Unix microseconds = `now.as_micros()` + this offset, e.g. on a board whose monotonic
    /// clock starts at boot once GPS time is known.
    OffsetMicros(i64),
    /// No wall clock: timestamps only count up from the persisted value, one per frame, and
    /// rise with correctly signed incoming frames.
    None,
}

impl WallClock {
    /// The signing timestamp this clock gives for `now` (0 without a clock).
    #[must_use]
    pub const fn timestamp(self, now: Instant) -> u64 {
        match self {
            Self::InstantIsUnix => signing::timestamp_from_unix_micros(now.as_micros()),
            Self::OffsetMicros(offset) => {
                signing::timestamp_from_unix_micros(now.as_micros().saturating_add_signed(offset))
            }
            Self::None => 0,
        }
    }
}

/// A table was full.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, thiserror::Error)]
#[error("table full: it holds at most {capacity} entries")]
pub struct CapacityError {
    /// The table's capacity.
    pub capacity: usize,
}

/// Signing settings of one link.
///
/// ```
/// use mavstack_channel::SigningConfig;
/// use mavstack_core::signing::SecretKey;
/// let mut signing = SigningConfig::new(SecretKey::new([7; 32]), 1);
/// assert_eq!(signing.allowed_unsigned(), &[109]); // RADIO_STATUS
/// signing.allow_unsigned(166).unwrap(); // ardupilotmega RADIO
/// signing.initial_timestamp = 1_234; // the value stored at the last PersistTimestamp event
/// ```
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct SigningConfig {
    keys: [Option<SecretKey>; MAX_KEYS],
    /// This link's id in the signature block of outgoing frames.
    pub link_id: u8,
    /// The timestamp persisted at the last [`Event::PersistTimestamp`](crate::Event::PersistTimestamp)
    /// (0 the first time): no timestamp below it is ever issued.
    pub initial_timestamp: u64,
    /// How `now` maps to wall-clock time.
    pub wall_clock: WallClock,
    /// How far ahead of the timestamp in use each persisted value reaches (10 µs units);
    /// 0 asks for persistence on every signed frame.
    pub persist_margin: u64,
    unsigned: [u32; MAX_UNSIGNED_IDS],
    unsigned_len: usize,
}

impl SigningConfig {
    /// Signing with `key` as the primary key and `link_id`, the wall clock from
    /// [`WallClock::InstantIsUnix`], and RADIO_STATUS (109) allowed unsigned.
    #[must_use]
    pub fn new(key: SecretKey, link_id: u8) -> Self {
        let mut unsigned = [0; MAX_UNSIGNED_IDS];
        unsigned[0] = RadioStatus::ID;
        Self {
            keys: [Some(key), None, None, None],
            link_id,
            initial_timestamp: 0,
            wall_clock: WallClock::InstantIsUnix,
            persist_margin: DEFAULT_PERSIST_MARGIN,
            unsigned,
            unsigned_len: 1,
        }
    }

    /// Adds a key that incoming signatures may match (outgoing frames keep using the primary
    /// key).
    ///
    /// # Errors
    /// [`CapacityError`] when the link already holds [`MAX_KEYS`] keys.
    pub fn add_key(&mut self, key: SecretKey) -> Result<(), CapacityError> {
        let slot = self
            .keys
            .iter_mut()
            .find(|k| k.is_none())
            .ok_or(CapacityError { capacity: MAX_KEYS })?;
        *slot = Some(key);
        Ok(())
    }

    /// Makes `key` the link's only key.
    pub(crate) fn replace_keys(&mut self, key: SecretKey) {
        self.keys = [Some(key), None, None, None];
    }

    /// The key outgoing frames are signed with.
    #[must_use]
    pub fn primary_key(&self) -> &SecretKey {
        // Slot 0 is filled by `new` and never emptied.
        self.keys().next().unwrap_or(&ZERO_KEY)
    }

    /// Every key, the primary first.
    pub fn keys(&self) -> impl Iterator<Item = &SecretKey> {
        self.keys.iter().flatten()
    }

    /// Accepts message `id` unsigned (and in MAVLink 1) on this link. Adding an id already
    /// on the list does nothing.
    ///
    /// # Errors
    /// [`CapacityError`] when the list already holds [`MAX_UNSIGNED_IDS`] ids.
    pub fn allow_unsigned(&mut self, id: u32) -> Result<(), CapacityError> {
        if self.is_allowed_unsigned(id) {
            return Ok(());
        }
        if self.unsigned_len == MAX_UNSIGNED_IDS {
            return Err(CapacityError {
                capacity: MAX_UNSIGNED_IDS,
            });
        }
        self.unsigned[self.unsigned_len] = id;
        self.unsigned_len += 1;
        Ok(())
    }

    /// Empties the unsigned allow-list (RADIO_STATUS included).
    pub fn clear_allowed_unsigned(&mut self) {
        self.unsigned_len = 0;
    }

    /// The message ids accepted unsigned.
    #[must_use]
    pub fn allowed_unsigned(&self) -> &[u32] {
        &self.unsigned[..self.unsigned_len]
    }

    /// Whether message `id` is accepted unsigned.
    #[must_use]
    pub fn is_allowed_unsigned(&self, id: u32) -> bool {
        self.allowed_unsigned().contains(&id)
    }
}

static ZERO_KEY: SecretKey = SecretKey::new([0; 32]);

/// What the link knows about one signing stream.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct SigningStream {
    /// Sender's system id.
    pub sysid: u8,
    /// Sender's component id.
    pub compid: u8,
    /// Sender's link id.
    pub link_id: u8,
    /// The timestamp of the last frame accepted on the stream.
    pub last_timestamp: u64,
}

/// The replay table: the last accepted timestamp of every stream.
#[derive(Clone, Debug)]
pub(crate) struct ReplayTable {
    streams: [SigningStream; MAX_STREAMS],
    len: usize,
}

impl ReplayTable {
    pub(crate) const fn new() -> Self {
        Self {
            streams: [SigningStream {
                sysid: 0,
                compid: 0,
                link_id: 0,
                last_timestamp: 0,
            }; MAX_STREAMS],
            len: 0,
        }
    }

    /// Checks `timestamp` for its stream and records it if fresh. Call only for frames whose
    /// signature has been verified. `local` is the link's current timestamp.
    pub(crate) fn check_and_record(
        &mut self,
        key: (u8, u8, u8),
        timestamp: u64,
        local: u64,
    ) -> Result<(), RejectReason> {
        let (sysid, compid, link_id) = key;
        let known = self.streams[..self.len]
            .iter_mut()
            .find(|s| (s.sysid, s.compid, s.link_id) == key);
        if let Some(stream) = known {
            if timestamp <= stream.last_timestamp {
                return Err(RejectReason::Replayed {
                    timestamp,
                    last: stream.last_timestamp,
                });
            }
            stream.last_timestamp = timestamp;
            return Ok(());
        }
        if timestamp.saturating_add(NEW_STREAM_WINDOW) < local {
            return Err(RejectReason::TooOld { timestamp, local });
        }
        if self.len == MAX_STREAMS {
            return Err(RejectReason::StreamTableFull);
        }
        self.streams[self.len] = SigningStream {
            sysid,
            compid,
            link_id,
            last_timestamp: timestamp,
        };
        self.len += 1;
        Ok(())
    }

    pub(crate) fn streams(&self) -> &[SigningStream] {
        &self.streams[..self.len]
    }
}

/// The signing state of a link that signs.
#[derive(Clone, Debug)]
pub(crate) struct LinkSigning {
    pub(crate) config: SigningConfig,
    /// The largest timestamp issued or accepted.
    timestamp: u64,
    /// The value last handed out for storage: timestamps below it are safe after a restart.
    reserved: u64,
    pending_persist: Option<u64>,
    pub(crate) replay: ReplayTable,
}

impl LinkSigning {
    pub(crate) fn new(config: SigningConfig) -> Self {
        let initial = config.initial_timestamp.min(MAX_TIMESTAMP);
        Self {
            timestamp: initial.saturating_sub(1),
            reserved: initial,
            pending_persist: None,
            replay: ReplayTable::new(),
            config,
        }
    }

    /// The link's current timestamp: the clock's, or the largest issued or accepted.
    pub(crate) fn current(&self, now: Instant) -> u64 {
        self.config.wall_clock.timestamp(now).max(self.timestamp)
    }

    /// The timestamp for the next outgoing frame: never below or equal to any before it.
    pub(crate) fn next_timestamp(&mut self, now: Instant) -> u64 {
        let t = self
            .config
            .wall_clock
            .timestamp(now)
            .max(self.timestamp.saturating_add(1))
            .min(MAX_TIMESTAMP);
        self.timestamp = t;
        if t >= self.reserved {
            self.reserved = t
                .saturating_add(self.config.persist_margin.max(1))
                .min(MAX_TIMESTAMP);
            self.pending_persist = Some(self.reserved);
        }
        t
    }

    /// Raises the timestamp to that of a correctly signed, accepted frame.
    pub(crate) fn raise(&mut self, timestamp: u64) {
        self.timestamp = self.timestamp.max(timestamp.min(MAX_TIMESTAMP));
    }

    /// The largest timestamp issued or accepted.
    pub(crate) const fn last_timestamp(&self) -> u64 {
        self.timestamp
    }

    /// Whether a value for the caller to store is due.
    pub(crate) const fn has_persist(&self) -> bool {
        self.pending_persist.is_some()
    }

    /// A value for the caller to store, if one is due.
    pub(crate) fn take_persist(&mut self) -> Option<u64> {
        self.pending_persist.take()
    }

    /// The index of the key `frame`'s signature matches, if any (constant-time compare for
    /// each key).
    pub(crate) fn verify<T: AsRef<[u8]>>(&self, frame: &Frame<T>) -> Option<u8> {
        self.config
            .keys()
            .position(|key| signing::verify(frame, key).is_ok())
            .and_then(|i| u8::try_from(i).ok())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replay_table_keys_streams_by_sysid_compid_link_id() {
        let mut t = ReplayTable::new();
        assert_eq!(t.check_and_record((1, 1, 0), 100, 100), Ok(()));
        assert_eq!(
            t.check_and_record((1, 1, 0), 100, 100),
            Err(RejectReason::Replayed {
                timestamp: 100,
                last: 100
            })
        );
        assert_eq!(t.check_and_record((1, 1, 1), 100, 100), Ok(()));
        assert_eq!(t.check_and_record((1, 2, 0), 100, 100), Ok(()));
        assert_eq!(t.check_and_record((2, 1, 0), 100, 100), Ok(()));
        assert_eq!(t.streams().len(), 4);
    }

    #[test]
    fn full_table_rejects_new_streams_but_serves_known_ones() {
        let mut t = ReplayTable::new();
        for i in 0..MAX_STREAMS {
            let id = u8::try_from(i + 1).unwrap();
            t.check_and_record((id, 1, 0), 10, 10).unwrap();
        }
        assert_eq!(
            t.check_and_record((200, 1, 0), 10, 10),
            Err(RejectReason::StreamTableFull)
        );
        assert_eq!(t.check_and_record((1, 1, 0), 11, 10), Ok(()));
    }

    #[test]
    fn timestamps_reserve_ahead_of_use() {
        let mut cfg = SigningConfig::new(SecretKey::new([1; 32]), 0);
        cfg.wall_clock = WallClock::None;
        cfg.persist_margin = 10;
        cfg.initial_timestamp = 50;
        let mut s = LinkSigning::new(cfg);
        assert_eq!(s.next_timestamp(Instant::ZERO), 50);
        assert_eq!(s.take_persist(), Some(60));
        for expected in 51..60 {
            assert_eq!(s.next_timestamp(Instant::ZERO), expected);
            assert_eq!(s.take_persist(), None);
        }
        assert_eq!(s.next_timestamp(Instant::ZERO), 60);
        assert_eq!(s.take_persist(), Some(70));
    }

    #[test]
    fn wall_clock_offsets() {
        let unix_2015 = signing::EPOCH_UNIX_SECS * 1_000_000;
        assert_eq!(
            WallClock::InstantIsUnix.timestamp(Instant::from_micros(unix_2015 + 100)),
            10
        );
        assert_eq!(
            WallClock::OffsetMicros(i64::try_from(unix_2015).unwrap())
                .timestamp(Instant::from_micros(20)),
            2
        );
        assert_eq!(WallClock::None.timestamp(Instant::MAX), 0);
    }

    #[test]
    fn key_and_allow_list_capacity() {
        let mut cfg = SigningConfig::new(SecretKey::new([1; 32]), 0);
        for _ in 1..MAX_KEYS {
            cfg.add_key(SecretKey::new([2; 32])).unwrap();
        }
        assert_eq!(
            cfg.add_key(SecretKey::new([3; 32])),
            Err(CapacityError { capacity: MAX_KEYS })
        );
        assert_eq!(cfg.primary_key().as_bytes(), &[1; 32]);
        assert_eq!(cfg.keys().count(), MAX_KEYS);
        for id in 0..u32::try_from(MAX_UNSIGNED_IDS).unwrap() - 1 {
            cfg.allow_unsigned(id).unwrap();
        }
        cfg.allow_unsigned(109).unwrap();
        assert!(cfg.allow_unsigned(4000).is_err());
        cfg.clear_allowed_unsigned();
        assert!(!cfg.is_allowed_unsigned(109));
    }
}
