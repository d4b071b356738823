//! The keys each section type knows, mavstack's own and the twelve filters, and what each
//! one sets.

use super::read::Kind;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Setting {
    TcpServerPort,
    ReportStats,
    DebugLogLevel,
    DeduplicationPeriod,
    SnifferSysid,
    Log,
    LogMode,
    MavlinkDialect,
    MinFreeSpace,
    MaxLogFiles,
    LogSystemId,
    LogTelemetry,
    Device,
    Baud,
    FlowControl,
    Mode,
    Address,
    Port,
    Filter,
    RetryTimeout,
    Group,
    /// One of [`FILTERS`], by index.
    MsgFilter(usize),
    MavlinkVersion,
    SigningKey,
    SigningLinkId,
    Trusted,
    Secure,
    RateLimit,
    BytesPerSecond,
}

const GENERAL_KEYS: &[(&str, Setting)] = &[
    ("TcpServerPort", Setting::TcpServerPort),
    ("ReportStats", Setting::ReportStats),
    ("DebugLogLevel", Setting::DebugLogLevel),
    ("DeduplicationPeriod", Setting::DeduplicationPeriod),
    ("SnifferSysid", Setting::SnifferSysid),
    ("Log", Setting::Log),
    ("LogMode", Setting::LogMode),
    ("MavlinkDialect", Setting::MavlinkDialect),
    ("MinFreeSpace", Setting::MinFreeSpace),
    ("MaxLogFiles", Setting::MaxLogFiles),
    ("LogSystemId", Setting::LogSystemId),
    ("LogTelemetry", Setting::LogTelemetry),
];

const UART_KEYS: &[(&str, Setting)] = &[
    ("Device", Setting::Device),
    ("Baud", Setting::Baud),
    ("FlowControl", Setting::FlowControl),
];

const UDP_KEYS: &[(&str, Setting)] = &[
    ("Address", Setting::Address),
    ("Mode", Setting::Mode),
    ("Port", Setting::Port),
    ("Filter", Setting::Filter),
];

const TCP_KEYS: &[(&str, Setting)] = &[
    ("Address", Setting::Address),
    ("Port", Setting::Port),
    ("RetryTimeout", Setting::RetryTimeout),
];

/// Keys of every endpoint section besides the filters: mavlink-router's `Group`, then mavstack's.
const ENDPOINT_KEYS: &[(&str, Setting)] = &[
    ("Group", Setting::Group),
    ("MavlinkVersion", Setting::MavlinkVersion),
    ("SigningKey", Setting::SigningKey),
    ("SigningLinkId", Setting::SigningLinkId),
    ("Trusted", Setting::Trusted),
    ("Secure", Setting::Secure),
    ("RateLimit", Setting::RateLimit),
    ("BytesPerSecond", Setting::BytesPerSecond),
];

/// The largest message id: 24 bits.
pub(super) const MAX_MSG_ID: u32 = 0xFF_FFFF;

/// A filter key, the link option it becomes, and the largest id it holds.
pub(super) struct FilterKey {
    pub(super) conf: &'static str,
    pub(super) option: &'static str,
    pub(super) max: u32,
}

/// The filters, in the order their options are written. `Filter` (UDP only) adds to the first.
pub(super) const FILTERS: [FilterKey; 12] = [
    FilterKey {
        conf: "AllowMsgIdOut",
        option: "allow_msg_out",
        max: MAX_MSG_ID,
    },
    FilterKey {
        conf: "BlockMsgIdOut",
        option: "block_msg_out",
        max: MAX_MSG_ID,
    },
    FilterKey {
        conf: "AllowSrcCompOut",
        option: "allow_src_comp_out",
        max: 255,
    },
    FilterKey {
        conf: "BlockSrcCompOut",
        option: "block_src_comp_out",
        max: 255,
    },
    FilterKey {
        conf: "AllowSrcSysOut",
        option: "allow_src_sys_out",
        max: 255,
    },
    FilterKey {
        conf: "BlockSrcSysOut",
        option: "block_src_sys_out",
        max: 255,
    },
    FilterKey {
        conf: "AllowMsgIdIn",
        option: "allow_msg_in",
        max: MAX_MSG_ID,
    },
    FilterKey {
        conf: "BlockMsgIdIn",
        option: "block_msg_in",
        max: MAX_MSG_ID,
    },
    FilterKey {
        conf: "AllowSrcCompIn",
        option: "allow_src_comp_in",
        max: 255,
    },
    FilterKey {
        conf: "BlockSrcCompIn",
        option: "block_src_comp_in",
        max: 255,
    },
    FilterKey {
        conf: "AllowSrcSysIn",
        option: "allow_src_sys_in",
        max: 255,
    },
    FilterKey {
        conf: "BlockSrcSysIn",
        option: "block_src_sys_in",
        max: 255,
    },
];

/// A key of a section type, as mavlink-router spells it.
pub(super) fn lookup(kind: Kind, key: &str) -> Option<(&'static str, Setting)> {
    let specific = match kind {
        Kind::General => return find_key(GENERAL_KEYS, key),
        Kind::Uart => UART_KEYS,
        Kind::Udp => UDP_KEYS,
        Kind::Tcp => TCP_KEYS,
    };
    find_key(specific, key)
        .or_else(|| find_key(ENDPOINT_KEYS, key))
        .or_else(|| {
            FILTERS
                .iter()
                .enumerate()
                .find(|(_, f)| f.conf.eq_ignore_ascii_case(key))
                .map(|(i, f)| (f.conf, Setting::MsgFilter(i)))
        })
}

fn find_key(table: &[(&'static str, Setting)], key: &str) -> Option<(&'static str, Setting)> {
    table
        .iter()
        .find(|(name, _)| name.eq_ignore_ascii_case(key))
        .copied()
}
