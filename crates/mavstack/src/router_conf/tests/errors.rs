//! The reader's errors: their lines and messages, unknown and missing keys, bad values, keys
//! never shown, and input that must never panic it.

use super::*;

#[test]
fn error_display_is_line_then_message() {
    let e = ConfError {
        line: 12,
        message: "x".to_owned(),
    };
    assert_eq!(e.to_string(), "line 12: x");
}

#[test]
fn line_errors() {
    assert_eq!(
        error("[General]\nReportStats\n"),
        "line 2: expected a [section] header, KEY = VALUE or a comment, found \"ReportStats\""
    );
    assert_eq!(
        error("[General]\n= 1\n"),
        "line 2: missing key before '=' in \"= 1\""
    );
    assert_eq!(
        error("[General]\nReportStats =  \n"),
        "line 2: General: \"ReportStats\" has no value"
    );
    assert_eq!(
        error("Port = 1\n"),
        "line 1: key \"Port\" comes before any [section] header"
    );
}

#[test]
fn section_header_errors() {
    let cases = [
        ("[General", "section header \"[General\" has no closing ']'"),
        (
            "[General]x",
            "unexpected text after ']' in section header \"[General]x\"",
        ),
        (
            "[UdpEndpoint a]]",
            "unexpected text after ']' in section header \"[UdpEndpoint a]]\"",
        ),
        (
            "[ General]",
            "section header \"[ General]\" has a space after '[' or before ']'",
        ),
        (
            "[UdpEndpoint a ]",
            "section header \"[UdpEndpoint a ]\" has a space after '[' or before ']'",
        ),
        (
            "[UdpEndpoint\ta]",
            "section header \"[UdpEndpoint\\ta]\" holds whitespace other than a space",
        ),
        (
            "[UdpEndpoint a b]",
            "section header \"[UdpEndpoint a b]\" has more than one space: a section name cannot contain spaces",
        ),
        (
            "[UdpEndpoint  a]",
            "section header \"[UdpEndpoint  a]\" has more than one space: a section name cannot contain spaces",
        ),
        (
            "[UdpEndpoint]",
            "section \"[UdpEndpoint]\" needs a name: [UdpEndpoint NAME]",
        ),
        (
            "[tcpendpoint]",
            "section \"[tcpendpoint]\" needs a name: [TcpEndpoint NAME]",
        ),
        (
            "[General main]",
            "section \"[General main]\" has a name; [General] takes none",
        ),
        (
            "[Log]",
            "unknown section \"[Log]\"; expected [General], [UartEndpoint NAME], [UdpEndpoint NAME] or [TcpEndpoint NAME]",
        ),
        (
            "[]",
            "unknown section \"[]\"; expected [General], [UartEndpoint NAME], [UdpEndpoint NAME] or [TcpEndpoint NAME]",
        ),
        (
            "[TcpServer x]",
            "unknown section \"[TcpServer x]\"; expected [General], [UartEndpoint NAME], [UdpEndpoint NAME] or [TcpEndpoint NAME]",
        ),
        (
            "[UdpEndpoint a&b]",
            "UdpEndpoint \"a&b\": a name must not contain '&', '?' or '='",
        ),
        (
            "[UartEndpoint x=y]",
            "UartEndpoint \"x=y\": a name must not contain '&', '?' or '='",
        ),
        (
            "[TcpEndpoint why?]",
            "TcpEndpoint \"why?\": a name must not contain '&', '?' or '='",
        ),
    ];
    for (header, message) in cases {
        assert_eq!(
            error(&format!("\n{header}\n")),
            format!("line 2: {message}"),
            "{header}"
        );
    }
    let long = format!("[UdpEndpoint {}]", "n".repeat(89));
    assert_eq!(
        error(&long),
        format!(
            "line 1: section header \"[UdpEndpoint {}\"... is longer than 100 characters",
            "n".repeat(47)
        )
    );
    // 100 characters between the brackets are allowed.
    let name = "n".repeat(88);
    let ok = format!("[UdpEndpoint {name}]\nMode = normal\nAddress = 1.2.3.4\n");
    assert_eq!(links(&ok), [format!("udpout:1.2.3.4:14550?name={name}")]);
}

#[test]
fn unknown_keys_are_errors() {
    assert_eq!(
        error("[General]\nTcpServer = 1\n"),
        "line 2: General: unknown key \"TcpServer\""
    );
    assert_eq!(
        error("[UdpEndpoint a]\nMode = server\nBaud = 57600\n"),
        "line 3: UdpEndpoint \"a\": unknown key \"Baud\""
    );
    assert_eq!(
        error("[UartEndpoint a]\nDevice = /dev/ttyS0\nAddress = 1.2.3.4\n"),
        "line 3: UartEndpoint \"a\": unknown key \"Address\""
    );
    assert_eq!(
        error("[TcpEndpoint a]\nAllow Msg Id Out = 1\n"),
        "line 2: TcpEndpoint \"a\": unknown key \"Allow Msg Id Out\""
    );
    assert_eq!(
        error("[UdpEndpoint a]\nReportStats = 1\n"),
        "line 2: UdpEndpoint \"a\": unknown key \"ReportStats\""
    );
    assert_eq!(
        error("[General]\nMavlinkVersion = 1\n"),
        "line 2: General: unknown key \"MavlinkVersion\""
    );
}

#[test]
fn missing_required_keys() {
    let cases = [
        (
            "[UdpEndpoint a]\nMode = normal\n",
            "UdpEndpoint \"a\": missing required key Address",
        ),
        (
            "[UdpEndpoint a]\nAddress = 1.2.3.4\nPort = 1\n",
            "UdpEndpoint \"a\": missing required key Mode (normal, server or eavesdropping)",
        ),
        (
            "[UdpEndpoint a]\nAddress = 0.0.0.0\nMode = server\n",
            "UdpEndpoint \"a\": missing required key Port (required in server mode)",
        ),
        (
            "[UdpEndpoint a]\nAddress = 0.0.0.0\nMode = eavesdropping\n",
            "UdpEndpoint \"a\": missing required key Port (required in server mode)",
        ),
        (
            "[TcpEndpoint a]\nPort = 1\n",
            "TcpEndpoint \"a\": missing required key Address",
        ),
        (
            "[TcpEndpoint a]\nAddress = 1.2.3.4\n",
            "TcpEndpoint \"a\": missing required key Port",
        ),
        (
            "[UartEndpoint a]\nBaud = 57600\n",
            "UartEndpoint \"a\": missing required key Device",
        ),
    ];
    for (text, message) in cases {
        assert_eq!(
            error(&format!("\n{text}")),
            format!("line 2: {message}"),
            "{text}"
        );
    }
}

#[test]
fn bad_values() {
    let udp = "[UdpEndpoint alpha]\nMode = server\nAddress = 0.0.0.0\nPort = 1\n";
    let uart = "[UartEndpoint alpha]\nDevice = /dev/ttyS0\n";
    let cases = [
        (
            format!("{udp}Port = 14a50"),
            "UdpEndpoint \"alpha\": Port \"14a50\" is not a number 1-65535",
        ),
        (
            format!("{udp}Port = 65536"),
            "UdpEndpoint \"alpha\": Port \"65536\" is not a number 1-65535",
        ),
        (
            format!("{udp}Port = 0"),
            "UdpEndpoint \"alpha\": Port \"0\" is not a number 1-65535",
        ),
        (
            format!("{udp}Port = -1"),
            "UdpEndpoint \"alpha\": Port \"-1\" is not a number 1-65535",
        ),
        (
            format!("{udp}Mode = client"),
            "UdpEndpoint \"alpha\": Mode \"client\" is not normal, server or eavesdropping",
        ),
        (
            format!("{udp}Address = localhost"),
            "UdpEndpoint \"alpha\": Address \"localhost\" is not an IPv4 address or an IPv6 address in brackets",
        ),
        (
            format!("{udp}Address = 256.0.0.1"),
            "UdpEndpoint \"alpha\": Address \"256.0.0.1\" is not an IPv4 address or an IPv6 address in brackets",
        ),
        (
            format!("{udp}Address = 0.0.0.0:14550"),
            "UdpEndpoint \"alpha\": Address \"0.0.0.0:14550\" is not an IPv4 address or an IPv6 address in brackets",
        ),
        (
            format!("{udp}Trusted = yes"),
            "UdpEndpoint \"alpha\": Trusted \"yes\" is not true, false or a number",
        ),
        (
            format!("{udp}Secure = on"),
            "UdpEndpoint \"alpha\": Secure \"on\" is not true, false or a number",
        ),
        (
            format!("{udp}Group = a # b\nFlowControl = 1"),
            "UdpEndpoint \"alpha\": unknown key \"FlowControl\"",
        ),
        (
            format!("{udp}MavlinkVersion = 3"),
            "UdpEndpoint \"alpha\": MavlinkVersion \"3\" is not 1, 2 or auto",
        ),
        (
            format!("{udp}MavlinkVersion = v2"),
            "UdpEndpoint \"alpha\": MavlinkVersion \"v2\" is not 1, 2 or auto",
        ),
        (
            format!("{udp}SigningKey = abcd"),
            "UdpEndpoint \"alpha\": SigningKey is not 64 hex digits (found 4 characters)",
        ),
        (
            format!("{udp}SigningKey = {}", "g".repeat(64)),
            "UdpEndpoint \"alpha\": SigningKey is not 64 hex digits (found a character that is not a hex digit)",
        ),
        (
            format!("{udp}SigningKey = {KEY}0"),
            "UdpEndpoint \"alpha\": SigningKey is not 64 hex digits (found 65 characters)",
        ),
        (
            format!("{udp}MavlinkVersion = 1\nSigningKey = {KEY}"),
            "UdpEndpoint \"alpha\": SigningKey needs MAVLink 2 but MavlinkVersion is 1",
        ),
        (
            format!("{udp}SigningLinkId = 256"),
            "UdpEndpoint \"alpha\": SigningLinkId \"256\" is not a number 0-255",
        ),
        (
            format!("{udp}BytesPerSecond = fast"),
            "UdpEndpoint \"alpha\": BytesPerSecond \"fast\" is not an unsigned number",
        ),
        (
            format!("{udp}RateLimit = 30:10&x"),
            "UdpEndpoint \"alpha\": RateLimit \"30:10&x\" must not contain '&', '?' or '='",
        ),
        (
            format!("{udp}RateLimit = 30:10 33:5"),
            "UdpEndpoint \"alpha\": RateLimit \"30:10 33:5\" has an item \"30:10 33:5\" with a space; separate items with commas",
        ),
        (
            format!("{udp}AllowSrcSysOut = 1,300"),
            "UdpEndpoint \"alpha\": AllowSrcSysOut \"1,300\": item \"300\" is not a number 0-255",
        ),
        (
            format!("{udp}BlockSrcCompIn = -1"),
            "UdpEndpoint \"alpha\": BlockSrcCompIn \"-1\": item \"-1\" is not a number 0-255",
        ),
        (
            format!("{udp}AllowMsgIdIn = 0x10"),
            "UdpEndpoint \"alpha\": AllowMsgIdIn \"0x10\": item \"0x10\" is not a number 0-16777215",
        ),
        (
            format!("{udp}BlockMsgIdOut = 16777216"),
            "UdpEndpoint \"alpha\": BlockMsgIdOut \"16777216\": item \"16777216\" is not a number 0-16777215",
        ),
        (
            format!("{udp}AllowMsgIdOut = 1 2 3"),
            "UdpEndpoint \"alpha\": AllowMsgIdOut \"1 2 3\": item \"1 2 3\" is not a number 0-16777215; separate items with commas",
        ),
        (
            format!("{uart}Baud = 0"),
            "UartEndpoint \"alpha\": Baud \"0\": item \"0\" is not a number 1-4294967295",
        ),
        (
            format!("{uart}Baud = 57600 115200"),
            "UartEndpoint \"alpha\": Baud \"57600 115200\": item \"57600 115200\" is not a number 1-4294967295; separate items with commas",
        ),
        (
            format!("{uart}FlowControl = maybe"),
            "UartEndpoint \"alpha\": FlowControl \"maybe\" is not true, false or a number",
        ),
        (
            format!("{uart}Device = /dev/tty,1"),
            "UartEndpoint \"alpha\": Device \"/dev/tty,1\" must not contain ',', '&', '?' or '='",
        ),
        (
            "[TcpEndpoint alpha]\nAddress = 1.2.3.4\nPort = 1\nRetryTimeout = soon".to_owned(),
            "TcpEndpoint \"alpha\": RetryTimeout \"soon\" is not a whole number of seconds",
        ),
        (
            "[TcpEndpoint alpha]\nAddress = 1.2.3.4\nPort = 1\nRetryTimeout = 0x80000000"
                .to_owned(),
            "TcpEndpoint \"alpha\": RetryTimeout \"0x80000000\" is not a whole number of seconds",
        ),
    ];
    for (text, message) in &cases {
        let line = text.lines().count();
        assert_eq!(error(text), format!("line {line}: {message}"), "{text}");
    }
}

#[test]
fn bad_general_values() {
    let cases = [
        (
            "TcpServerPort = 70000",
            "TcpServerPort \"70000\" is not a number 0-65535",
        ),
        (
            "ReportStats = yes",
            "ReportStats \"yes\" is not true, false or a number",
        ),
        (
            "DebugLogLevel = verbose",
            "DebugLogLevel \"verbose\" is not error, warning, info, debug or trace",
        ),
        (
            "DeduplicationPeriod = 100ms",
            "DeduplicationPeriod \"100ms\" is not an unsigned number",
        ),
        (
            "SnifferSysid = -1",
            "SnifferSysid \"-1\" is not an unsigned number",
        ),
        (
            "LogMode = armed",
            "LogMode \"armed\" is not always or while-armed",
        ),
        (
            "MavlinkDialect = px4",
            "MavlinkDialect \"px4\" is not auto, common or ardupilotmega",
        ),
        (
            "MinFreeSpace = 1G",
            "MinFreeSpace \"1G\" is not an unsigned number",
        ),
        (
            "MaxLogFiles = many",
            "MaxLogFiles \"many\" is not an unsigned number",
        ),
        ("LogSystemId = 0", "LogSystemId \"0\" is not a number 1-255"),
        (
            "LogSystemId = 256",
            "LogSystemId \"256\" is not a number 1-255",
        ),
        (
            "LogTelemetry = enabled",
            "LogTelemetry \"enabled\" is not true, false or a number",
        ),
    ];
    for (entry, message) in cases {
        assert_eq!(
            error(&format!("[General]\n{entry}\n")),
            format!("line 2: General: {message}")
        );
    }
    // A long value is cut short in the message.
    let long = "9".repeat(1000);
    assert_eq!(
        error(&format!("[General]\nTcpServerPort = {long}\n")),
        format!(
            "line 2: General: TcpServerPort \"{}\"... is not a number 0-65535",
            "9".repeat(60)
        )
    );
}

#[test]
fn a_signing_key_never_appears_in_an_error() {
    let secret = format!("{}x", &KEY[..63]);
    let text = format!("[UdpEndpoint a]\nSigningKey = {secret}\n");
    assert!(!error(&text).contains(&secret[..20]));
}

#[test]
fn every_mavlink_router_key_is_known() {
    // mavlink-router's own tables (src/main.cpp, src/logendpoint.cpp, src/endpoint.cpp).
    let general = [
        "TcpServerPort",
        "ReportStats",
        "DebugLogLevel",
        "DeduplicationPeriod",
        "SnifferSysid",
        "Log",
        "LogMode",
        "MavlinkDialect",
        "MinFreeSpace",
        "MaxLogFiles",
        "LogSystemId",
        "LogTelemetry",
    ];
    let filters = [
        "AllowMsgIdOut",
        "BlockMsgIdOut",
        "AllowSrcCompOut",
        "BlockSrcCompOut",
        "AllowSrcSysOut",
        "BlockSrcSysOut",
        "AllowMsgIdIn",
        "BlockMsgIdIn",
        "AllowSrcCompIn",
        "BlockSrcCompIn",
        "AllowSrcSysIn",
        "BlockSrcSysIn",
        "Group",
    ];
    for key in general {
        assert_eq!(
            lookup(Kind::General, &key.to_ascii_lowercase()).map(|k| k.0),
            Some(key)
        );
    }
    for (kind, own) in [
        (Kind::Uart, &["Baud", "Device", "FlowControl"][..]),
        (Kind::Udp, &["Address", "Mode", "Port", "Filter"][..]),
        (Kind::Tcp, &["Address", "Port", "RetryTimeout"][..]),
    ] {
        for key in own.iter().chain(&filters) {
            assert_eq!(
                lookup(kind, &key.to_ascii_uppercase()).map(|k| k.0),
                Some(*key)
            );
        }
    }
}

/// A small deterministic generator for the garbage test.
struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn below(&mut self, n: usize) -> usize {
        usize::try_from(self.next() % n as u64).unwrap_or(0)
    }
}

/// Every option of a link is `key=value` with a value free of `&`, `?` and `=`.
fn assert_well_formed(conf: &RouterConf) {
    for l in &conf.links {
        let (connection, options) = l.link.split_once('?').expect("options");
        assert!(
            ["udpin:", "udpout:", "tcp:", "serial:"]
                .iter()
                .any(|s| connection.starts_with(s)),
            "{connection}"
        );
        assert!(options.starts_with(&format!("name={}", l.name)));
        for option in options.split('&') {
            assert_eq!(option.matches('=').count(), 1, "{}", l.link);
        }
    }
}

#[test]
fn garbage_never_panics() {
    const PIECES: &[&str] = &[
        "[",
        "]",
        "=",
        "#",
        ";",
        " ",
        "\t",
        "\r",
        "\n",
        "\x0b",
        ",",
        ":",
        "&",
        "?",
        "\"",
        "é",
        "\u{0}",
        "[General]\n",
        "[UdpEndpoint a]\n",
        "[udpendpoint A]\n",
        "[TcpEndpoint t]\n",
        "[UartEndpoint u]\n",
        "Mode = server\n",
        "Mode=normal\n",
        "Address = 0.0.0.0\n",
        "Address = [::1]\n",
        "Port = 14550\n",
        "Port=",
        "0x",
        "0",
        "9",
        "-",
        "+",
        "Device = /dev/x\n",
        "Baud = 1,2\n",
        "Filter = 1\n",
        "AllowMsgIdOut = ",
        "SigningKey = ",
        KEY,
        "MavlinkVersion = 1\n",
        "TcpServerPort = ",
        "ReportStats = ",
        "Group = g\n",
        "RateLimit = ",
        "[",
        "[]",
        "\u{10FFFF}",
        "ä]",
    ];
    let mut rng = XorShift(0x9E37_79B9_7F4A_7C15);
    for _ in 0..20_000 {
        let mut text = String::new();
        for _ in 0..rng.below(40) {
            text.push_str(PIECES[rng.below(PIECES.len())]);
        }
        if let Ok(conf) = parse(&text) {
            assert_well_formed(&conf);
        }
    }
    // Random characters, including every ASCII control character.
    for _ in 0..5_000 {
        let text: String = (0..rng.below(200))
            .map(|_| char::from_u32(u32::try_from(rng.below(0x250)).unwrap_or(0)).unwrap_or('x'))
            .collect();
        if let Ok(conf) = parse(&text) {
            assert_well_formed(&conf);
        }
    }
    // Every prefix of the sample.
    for (cut, _) in CONFIG_SAMPLE.char_indices() {
        if let Ok(conf) = parse(&CONFIG_SAMPLE[..cut]) {
            assert_well_formed(&conf);
        }
    }
}

#[test]
fn long_lines_are_handled() {
    let long = "x".repeat(1 << 20);
    assert!(parse(&long).is_err());
    assert!(parse(&format!("[{long}]")).is_err());
    assert!(parse(&format!("[General]\nLog = {long}\n")).is_ok());
    let message = error(&format!("[General]\n{long}\n"));
    assert!(message.len() < 200, "{message}");
    let list = format!(
        "[TcpEndpoint t]\nAddress = 1.2.3.4\nPort = 1\nAllowMsgIdOut = {}\n",
        "1,".repeat(100_000)
    );
    let conf = parse(&list).expect("parses");
    assert_well_formed(&conf);
}

/// Found by the `router_conf` fuzz target: a link id without a key made a link string the
/// link parser refuses.
#[test]
fn a_link_id_without_a_key_is_an_error() {
    let text = "[UartEndpoint fc]\nDevice = /dev/ttyS1\nSigningLinkId = 2\n";
    let err = parse(text).err().map(|e| e.to_string());
    assert_eq!(
        err.as_deref(),
        Some("line 1: UartEndpoint \"fc\": SigningLinkId without a SigningKey")
    );
    #[cfg(feature = "fuzzing")]
    fuzz_router_conf(text.as_bytes());
}
