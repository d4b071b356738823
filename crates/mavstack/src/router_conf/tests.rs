//! Tests of the `main.conf` reader: mavlink-router's sample file and syntax, every key's
//! decision (honoured, warned about, refused) and the errors' positions.

use super::keys::lookup;
use super::read::Kind;
use super::*;

mod errors;

/// `examples/config.sample` of github.com/mavlink-router/mavlink-router at commit
/// c20337bbc61abda21463e7482172d58b654e66b6 (blob 66b1c7e6ea1095139d1d08918b01ed23106ed924),
/// verbatim (Apache-2.0). It is the only configuration file in `examples/`.
const CONFIG_SAMPLE: &str = include_str!("../../tests/data/config.sample");

fn conf_link(name: &str, line: usize, link: &str) -> ConfLink {
    ConfLink {
        name: name.to_owned(),
        line,
        link: link.to_owned(),
    }
}

fn links(text: &str) -> Vec<String> {
    parse(text)
        .expect("parses")
        .links
        .into_iter()
        .map(|l| l.link)
        .collect()
}

fn error(text: &str) -> String {
    parse(text).expect_err("is rejected").to_string()
}

fn ignored(list: &[(usize, &str)]) -> Vec<(usize, String)> {
    list.iter()
        .map(|&(line, key)| (line, key.to_owned()))
        .collect()
}

const KEY: &str = "00112233445566778899aabbccddeeff00112233445566778899AABBCCDDEEFF";

#[test]
fn config_sample_parses_to_its_four_endpoints() {
    let conf = parse(CONFIG_SAMPLE).expect("the sample parses");
    assert_eq!(conf.general, General::default());
    assert_eq!(
        conf.links,
        [
            conf_link("alpha", 199, "serial:/dev/ttyS0:52000?name=alpha"),
            conf_link("bravo", 234, "udpin:0.0.0.0:10000?name=bravo"),
            conf_link("charlie", 240, "udpout:127.0.0.1:11000?name=charlie"),
            conf_link("delta", 272, "tcp:127.0.0.1:25760?name=delta"),
        ]
    );
}

#[test]
fn config_sample_with_its_templates_filled_in() {
    // Every key the sample documents, given a value, in the sample's spelling.
    let text = CONFIG_SAMPLE
        .replace("#ReportStats = false", "ReportStats = true")
        .replace("#DebugLogLevel = info", "DebugLogLevel = debug")
        .replace("#DeDuplicationPeriod = 0", "DeDuplicationPeriod = 100")
        .replace("#TcpServerPort = 5760", "TcpServerPort = 0")
        .replace("#MavlinkDialect = auto", "MavlinkDialect = ArduPilotMega")
        .replace("#Log = /some/path", "Log = /some/path")
        .replace("#LogMode = always", "LogMode = while-armed")
        .replace("#LogSystemId = ", "LogSystemId = 1")
        .replace("#MinFreeSpace = 0", "MinFreeSpace = 1000000")
        .replace("#MaxLogFiles = 0", "MaxLogFiles = 10")
        .replace("#SnifferSysid=254", "SnifferSysid=254")
        .replace("# LogTelemetry = false", "LogTelemetry = true")
        .replace(
            "Baud = 52000",
            "Baud = 52000, 57600\nFlowControl = true\nGroup = radios",
        )
        .replace(
            "Port = 11000",
            "Port = 11000\nAllowMsgIdOut = 0, 1,2\nBlockSrcSysIn = 255",
        )
        .replace("Port = 25760", "Port = 25760\nRetryTimeout = 0");
    let conf = parse(&text).expect("the filled-in sample parses");
    assert_eq!(
        conf.general,
        General {
            tcp_server_port: Some(0),
            log_dir: Some(PathBuf::from("/some/path")),
            dedup_ms: Some(100),
            report_stats: true,
            dialect: Some("ardupilotmega".to_owned()),
            ignored: ignored(&[
                (35, "DebugLogLevel"),
                (68, "LogMode"),
                (73, "LogSystemId"),
                (78, "MinFreeSpace"),
                (83, "MaxLogFiles"),
                (89, "SnifferSysid"),
                (95, "LogTelemetry"),
                (201, "Baud (rates after the first)"),
                (202, "FlowControl"),
                (203, "Group"),
                (279, "RetryTimeout"),
            ]),
        }
    );
    assert_eq!(
        conf.links
            .iter()
            .map(|l| l.link.as_str())
            .collect::<Vec<_>>(),
        [
            "serial:/dev/ttyS0:52000?name=alpha",
            "udpin:0.0.0.0:10000?name=bravo",
            "udpout:127.0.0.1:11000?name=charlie&allow_msg_out=0,1,2&block_src_sys_in=255",
            "tcp:127.0.0.1:25760?name=delta",
        ]
    );
}

#[test]
fn every_filter_maps_to_its_option_in_order() {
    let text = "[TcpEndpoint t]\nAddress = 10.0.0.1\nPort = 5760\n\
        BlockSrcSysIn = 12\nAllowSrcSysIn = 11\nBlockSrcCompIn = 10\nAllowSrcCompIn = 9\n\
        BlockMsgIdIn = 8\nAllowMsgIdIn = 7\nBlockSrcSysOut = 6\nAllowSrcSysOut = 5\n\
        BlockSrcCompOut = 4\nAllowSrcCompOut = 3\nBlockMsgIdOut = 2\nAllowMsgIdOut = 16777215\n";
    assert_eq!(
        links(text),
        [
            "tcp:10.0.0.1:5760?name=t&allow_msg_out=16777215&block_msg_out=2\
          &allow_src_comp_out=3&block_src_comp_out=4&allow_src_sys_out=5&block_src_sys_out=6\
          &allow_msg_in=7&block_msg_in=8&allow_src_comp_in=9&block_src_comp_in=10\
          &allow_src_sys_in=11&block_src_sys_in=12"
        ]
    );
}

#[test]
fn legacy_filter_and_allow_msg_id_out_fill_one_list() {
    let text = "[UdpEndpoint u]\nMode = normal\nAddress = 127.0.0.1\nPort = 14550\n\
        AllowMsgIdOut = 33\nFilter = 0 , 30\n";
    assert_eq!(
        links(text),
        ["udpout:127.0.0.1:14550?name=u&allow_msg_out=0,30,33"]
    );
    // Filter is a UDP key only, as in mavlink-router.
    assert_eq!(
        error("[TcpEndpoint t]\nAddress = 127.0.0.1\nPort = 1\nFilter = 0\n"),
        "line 4: TcpEndpoint \"t\": unknown key \"Filter\""
    );
}

#[test]
fn lists_are_comma_separated_with_optional_spaces() {
    let text = "[UdpEndpoint u]\nMode = normal\nAddress = 127.0.0.1\nPort = 1\n\
        AllowSrcCompOut = ,1,, 2 ,\t3,\nBlockSrcSysOut = ,\n";
    // Empty items are skipped; a list of none is no filter.
    assert_eq!(
        links(text),
        ["udpout:127.0.0.1:1?name=u&allow_src_comp_out=1,2,3"]
    );
}

#[test]
fn mavstack_keys_become_link_options_in_order() {
    let text = format!(
        "[UdpEndpoint gcs]\nBytesPerSecond = 0x400\nRateLimit = 30:10, 33:5\nTrusted = 1\n\
         Secure = TRUE\nSigningLinkId = 7\nSigningKey = {KEY}\nMavlinkVersion = Auto\n\
         BlockMsgIdOut = 1\nMode = server\nAddress = 0.0.0.0\nPort = 14550\n\
         [UartEndpoint legacy]\nDevice = /dev/ttyUSB0\nBaud = 57600\nMavlinkVersion = 1\n\
         Trusted = false\n[TcpEndpoint up]\nAddress = 127.0.0.1\nPort = 5760\n\
         MavlinkVersion = 2\nSecure = 0\n"
    );
    assert_eq!(
        links(&text),
        [
            format!(
                "udpin:0.0.0.0:14550?name=gcs&version=auto&key={KEY}&link_id=7&secure=true\
                 &trusted=true&block_msg_out=1&rate=30:10,33:5&bytes_per_s=1024"
            ),
            "serial:/dev/ttyUSB0:57600?name=legacy&version=1&trusted=false".to_owned(),
            "tcp:127.0.0.1:5760?name=up&version=2&secure=false".to_owned(),
        ]
    );
}

#[test]
fn udp_modes_and_ports_follow_mavlink_router() {
    let text = "[UdpEndpoint a]\nMode = Normal\nAddress = 192.168.1.255\n\
        [UdpEndpoint b]\nMode = Eavesdropping\nAddress = 0.0.0.0\nPort = 14551\n\
        [UdpEndpoint c]\nMode = SERVER\nAddress = 127.0.0.1\nPort = 14552\n";
    assert_eq!(
        links(text),
        [
            "udpout:192.168.1.255:14550?name=a",
            "udpin:0.0.0.0:14551?name=b",
            "udpin:127.0.0.1:14552?name=c",
        ]
    );
}

#[test]
fn automatic_udp_port_moves_once_in_mavlink_routers_visiting_order() {
    // mavlink-router visits sections newest first: "third" is on another address, "late"
    // takes 14550, and "early" then finds 14550 taken on its address and gets 14551.
    let text = "[UdpEndpoint early]\nMode = normal\nAddress = 10.0.0.1\n\
        [UdpEndpoint late]\nMode = normal\nAddress = 10.0.0.1\n\
        [UdpEndpoint third]\nMode = normal\nAddress = 10.0.0.2\n";
    assert_eq!(
        links(text),
        [
            "udpout:10.0.0.1:14551?name=early",
            "udpout:10.0.0.1:14550?name=late",
            "udpout:10.0.0.2:14550?name=third",
        ]
    );
    // An explicit 14550 on the same address, visited first, moves it too; a third one
    // without Port gets 14551 again: it is not a search for a free port.
    let text = "[UdpEndpoint x]\nMode = normal\nAddress = 10.0.0.1\n\
        [UdpEndpoint y]\nMode = normal\nAddress = 10.0.0.1\n\
        [UdpEndpoint z]\nMode = server\nAddress = 10.0.0.1\nPort = 14550\n";
    assert_eq!(
        links(text),
        [
            "udpout:10.0.0.1:14551?name=x",
            "udpout:10.0.0.1:14551?name=y",
            "udpin:10.0.0.1:14550?name=z",
        ]
    );
}

#[test]
fn uart_baud_defaults_to_115200_and_uses_the_first_of_a_list() {
    let text = "[UartEndpoint a]\nDevice = /dev/ttyS1\n\
        [UartEndpoint b]\nDevice = /dev/ttyS2\nBaud = ,\n\
        [UartEndpoint c]\nDevice = /dev/serial/by-id/usb-FTDI_FT232R-if00-port0\nBaud = 921600, 57600\n";
    let conf = parse(text).expect("parses");
    assert_eq!(
        conf.links
            .iter()
            .map(|l| l.link.as_str())
            .collect::<Vec<_>>(),
        [
            "serial:/dev/ttyS1:115200?name=a",
            "serial:/dev/ttyS2:115200?name=b",
            "serial:/dev/serial/by-id/usb-FTDI_FT232R-if00-port0:921600?name=c",
        ]
    );
    assert_eq!(
        conf.general.ignored,
        ignored(&[(8, "Baud (rates after the first)")])
    );
}

#[test]
fn ipv6_addresses_go_in_brackets() {
    let text = "[UdpEndpoint any]\nMode = server\nAddress = [::]\nPort = 14550\n\
        [UdpEndpoint mcast]\nMode = normal\nAddress = [ff02::1]\nPort = 14551\n\
        [TcpEndpoint loop]\nAddress = [::1]\nPort = 5760\n\
        [TcpEndpoint upper]\nAddress = [FE80::1]\nPort = 5761\n";
    assert_eq!(
        links(text),
        [
            "udpin:[::]:14550?name=any",
            "udpout:[ff02::1]:14551?name=mcast",
            "tcp:[::1]:5760?name=loop",
            "tcp:[FE80::1]:5761?name=upper",
        ]
    );
    assert_eq!(
        error("[UdpEndpoint a]\nMode = server\nAddress = ::1\nPort = 1\n"),
        "line 3: UdpEndpoint \"a\": Address \"::1\" is an IPv6 address without brackets; \
         write it as [ADDRESS]"
    );
    assert_eq!(
        error("[TcpEndpoint a]\nAddress = [::g]\nPort = 1\n"),
        "line 2: TcpEndpoint \"a\": Address \"[::g]\" is not an IPv6 address"
    );
}

#[test]
fn comments_blank_lines_and_whitespace() {
    let text = "# a comment\n; another\n   # indented\n\n\t\n[General]\r\n\
        \x0b TcpServerPort\t=\t6000 \x0c\r\n;TcpServerPort = 7000\n\
        [UdpEndpoint a] \r\n  Mode=server\r\nAddress= 0.0.0.0\nPort =14550\n#Port = 1\n";
    let conf = parse(text).expect("parses");
    assert_eq!(conf.general.tcp_server_port, Some(6000));
    assert_eq!(
        conf.links,
        [conf_link("a", 9, "udpin:0.0.0.0:14550?name=a")]
    );
    // There are no trailing comments: the '#' is part of the value.
    assert_eq!(
        error("[General]\nTcpServerPort = 5760 # default\n"),
        "line 2: General: TcpServerPort \"5760 # default\" is not a number 0-65535"
    );
    assert_eq!(
        error("[General] # general\n"),
        "line 1: unexpected text after ']' in section header \"[General] # general\""
    );
    assert_eq!(
        error(
            "[UdpEndpoint a]\nMode = server\nAddress = 0.0.0.0\nPort = 1\nAllowMsgIdOut = 0,1 # hb\n"
        ),
        "line 5: UdpEndpoint \"a\": AllowMsgIdOut \"0,1 # hb\": item \"1 # hb\" is not a number \
         0-16777215; a comment must be on a line of its own"
    );
}

#[test]
fn values_are_not_unquoted() {
    let conf = parse("[General]\nLog = \"/var/log/mav\"\n").expect("parses");
    assert_eq!(
        conf.general.log_dir,
        Some(PathBuf::from("\"/var/log/mav\""))
    );
    assert_eq!(
        error("[TcpEndpoint a]\nAddress = \"127.0.0.1\"\nPort = 1\n"),
        "line 2: TcpEndpoint \"a\": Address \"\\\"127.0.0.1\\\"\" is not an IPv4 address or \
         an IPv6 address in brackets"
    );
    // A value may hold '=' (the line splits at the first one) and keep inner spaces.
    let conf = parse("[General]\nLog = /var/log/a=b c\n").expect("parses");
    assert_eq!(conf.general.log_dir, Some(PathBuf::from("/var/log/a=b c")));
}

#[test]
fn sections_keys_and_values_are_case_insensitive() {
    let text = "[GENERAL]\nreportstats = TRUE\nMAVLINKDIALECT = Common\n\
        [udpendpoint Gcs]\nMODE = SeRvEr\naddress = 0.0.0.0\n\
        [UartEndpoint radio]\nDEVICE = /dev/ttyS0\n\
        [UDPENDPOINT gcs]\nport = 14550\nallowmsgidout = 0\n\
        [general]\nTcpServerPort = 5761\n";
    let conf = parse(text).expect("parses");
    assert!(conf.general.report_stats);
    assert_eq!(conf.general.dialect.as_deref(), Some("common"));
    assert_eq!(conf.general.tcp_server_port, Some(5761));
    // [UDPENDPOINT gcs] reopens [udpendpoint Gcs]: the first spelling and line are kept.
    assert_eq!(
        conf.links,
        [
            conf_link("Gcs", 4, "udpin:0.0.0.0:14550?name=Gcs&allow_msg_out=0"),
            conf_link("radio", 7, "serial:/dev/ttyS0:115200?name=radio"),
        ]
    );
}

#[test]
fn a_key_set_again_replaces_the_earlier_value() {
    let text = "[TcpEndpoint t]\nAddress = 1.2.3.4\nPort = bad\nPort = 5760\nport = 5761\n\
        AllowMsgIdOut = 1,2\n[TcpEndpoint t]\nALLOWMSGIDOUT = 3\n";
    assert_eq!(links(text), ["tcp:1.2.3.4:5761?name=t&allow_msg_out=3"]);
    // The line of a replaced key is where it was last set.
    assert_eq!(
        error("[General]\nReportStats = 1\nreportstats = maybe\n"),
        "line 3: General: ReportStats \"maybe\" is not true, false or a number"
    );
}

#[test]
fn boolean_spellings() {
    for (value, expected) in [
        ("true", true),
        ("TRUE", true),
        ("True", true),
        ("1", true),
        ("2", true),
        ("-1", true),
        ("0x1", true),
        ("false", false),
        ("FALSE", false),
        ("0", false),
        ("00", false),
        ("0x0", false),
    ] {
        let conf = parse(&format!("[General]\nReportStats = {value}\n")).expect(value);
        assert_eq!(conf.general.report_stats, expected, "{value}");
    }
    for value in ["yes", "no", "on", "off", "t", "1.0", "0x", "--1"] {
        assert_eq!(
            error(&format!("[General]\nReportStats = {value}\n")),
            format!("line 2: General: ReportStats \"{value}\" is not true, false or a number")
        );
    }
}

#[test]
fn numbers_are_read_like_strtoul_base_0() {
    let port = |value: &str| {
        parse(&format!("[General]\nTcpServerPort = {value}\n")).map(|c| c.general.tcp_server_port)
    };
    assert_eq!(port("5760"), Ok(Some(5760)));
    assert_eq!(port("+5760"), Ok(Some(5760)));
    assert_eq!(port("0x1680"), Ok(Some(5760)));
    assert_eq!(port("0X1680"), Ok(Some(5760)));
    assert_eq!(port("013200"), Ok(Some(5760))); // octal, as mavlink-router reads it
    assert_eq!(port("0"), Ok(Some(0)));
    assert_eq!(port("65535"), Ok(Some(65535)));
    for bad in [
        "65536",
        "-1",
        "08",
        "0x",
        "5760.0",
        "5_760",
        "1e3",
        "99999999999999999999999",
    ] {
        assert_eq!(
            port(bad).map_err(|e| e.message),
            Err(format!(
                "General: TcpServerPort \"{bad}\" is not a number 0-65535"
            ))
        );
    }
    let conf = parse("[General]\nDeduplicationPeriod = 0x64\n").expect("parses");
    assert_eq!(conf.general.dedup_ms, Some(100));
}

#[test]
fn a_last_line_without_newline_is_read() {
    // mavlink-router drops text after the last '\n'; reading it is more useful.
    assert_eq!(
        links("[TcpEndpoint t]\nAddress = 1.2.3.4\nPort = 1"),
        ["tcp:1.2.3.4:1?name=t"]
    );
}

#[test]
fn empty_input_and_empty_general() {
    assert_eq!(parse(""), Ok(RouterConf::default()));
    assert_eq!(
        parse("\n\n# nothing\n[General]\n"),
        Ok(RouterConf::default())
    );
}

#[test]
fn parse_dir_merges_like_a_conf_directory() {
    let files = [
        (
            "main.conf".to_owned(),
            "[General]\nTcpServerPort = 5760\nDebugLogLevel = info\n\
             [UdpEndpoint gcs]\nMode = server\nAddress = 0.0.0.0\nPort = 14550\n"
                .to_owned(),
        ),
        (
            "config.d/10-override.conf".to_owned(),
            "[udpendpoint GCS]\nPort = 14560\nMavlinkVersion = 1\n\
             [TcpEndpoint up]\nAddress = 10.0.0.1\nPort = 5760\n[general]\nTcpServerPort=0\n"
                .to_owned(),
        ),
    ];
    let conf = parse_dir(&files).expect("parses");
    assert_eq!(conf.general.tcp_server_port, Some(0));
    assert_eq!(conf.general.ignored, ignored(&[(3, "DebugLogLevel")]));
    assert_eq!(
        conf.links,
        [
            conf_link("gcs", 4, "udpin:0.0.0.0:14560?name=gcs&version=1"),
            conf_link("up", 4, "tcp:10.0.0.1:5760?name=up"),
        ]
    );
    assert_eq!(parse_dir(&[]), Ok(RouterConf::default()));
}

#[test]
fn parse_dir_names_the_file_of_an_error() {
    let main = (
        "main.conf".to_owned(),
        "[UdpEndpoint gcs]\nMode = server\n".to_owned(),
    );
    // The key is before any header of its own file, although main.conf ended in a section.
    let bad = (
        "config.d/a.conf".to_owned(),
        "\nAddress = 0.0.0.0\n".to_owned(),
    );
    assert_eq!(
        parse_dir(&[main.clone(), bad]),
        Err((
            "config.d/a.conf".to_owned(),
            ConfError {
                line: 2,
                message: "key \"Address\" comes before any [section] header".to_owned()
            }
        ))
    );
    // A bad value is reported in the file that set it.
    let bad = (
        "config.d/b.conf".to_owned(),
        "[UdpEndpoint gcs]\nPort = x\n".to_owned(),
    );
    let (file, error) = parse_dir(&[main.clone(), bad]).expect_err("is rejected");
    assert_eq!(
        (file.as_str(), error.to_string().as_str()),
        (
            "config.d/b.conf",
            "line 2: UdpEndpoint \"gcs\": Port \"x\" is not a number 1-65535"
        )
    );
    // A missing key is reported at the section's first header.
    let more = (
        "config.d/c.conf".to_owned(),
        "[UdpEndpoint gcs]\nPort = 1\n".to_owned(),
    );
    let (file, error) = parse_dir(&[main, more]).expect_err("is rejected");
    assert_eq!(
        (file.as_str(), error.to_string().as_str()),
        (
            "main.conf",
            "line 1: UdpEndpoint \"gcs\": missing required key Address"
        )
    );
}
