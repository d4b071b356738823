//! Values as mavlink-router reads them: C numbers and booleans, decimal lists, addresses, and
//! the characters a link string cannot hold.

use core::net::{Ipv4Addr, Ipv6Addr};

use super::read::{is_c_space, shown, trim};

/// C `strtoul(s, _, 0)` over the whole of `s`, without its wrap-around of negative numbers.
pub(super) fn c_unsigned(s: &str) -> Option<u64> {
    let s = s.strip_prefix('+').unwrap_or(s);
    let (digits, radix) = if let Some(hex) = s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        (hex, 16)
    } else if s.len() > 1 && s.starts_with('0') {
        (&s[1..], 8)
    } else {
        (s, 10)
    };
    if digits.is_empty() || !digits.chars().all(|c| c.is_digit(radix)) {
        return None;
    }
    u64::from_str_radix(digits, radix).ok()
}

/// C `strtol(s, _, 0)` over the whole of `s`, in the range of a 32-bit `int`.
pub(super) fn c_int(s: &str) -> Option<i32> {
    match s.strip_prefix('-') {
        Some(rest) if !rest.starts_with(['+', '-']) => {
            let magnitude = i64::try_from(c_unsigned(rest)?).ok()?;
            i32::try_from(-magnitude).ok()
        }
        Some(_) => None,
        None => i32::try_from(c_unsigned(s)?).ok(),
    }
}

/// mavlink-router's boolean: `true`, `false` (any case) or a number, non-zero being true.
pub(super) fn c_bool(s: &str) -> Option<bool> {
    if s.eq_ignore_ascii_case("true") {
        Some(true)
    } else if s.eq_ignore_ascii_case("false") {
        Some(false)
    } else {
        c_int(s).map(|n| n != 0)
    }
}

/// A comma-separated list of decimal numbers in `min..=max`; empty items are skipped.
pub(super) fn number_list(value: &str, min: u32, max: u32) -> Result<Vec<u32>, String> {
    let mut items = Vec::new();
    for item in value.split(',').map(trim).filter(|item| !item.is_empty()) {
        let number = Some(item)
            .filter(|item| item.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|item| item.parse::<u32>().ok())
            .filter(|n| (min..=max).contains(n));
        let Some(number) = number else {
            let hint = if item.contains(['#', ';']) {
                "; a comment must be on a line of its own"
            } else if item.contains(is_c_space) {
                "; separate items with commas"
            } else {
                ""
            };
            return Err(format!(
                "item {} is not a number {min}-{max}{hint}",
                shown(item)
            ));
        };
        items.push(number);
    }
    Ok(items)
}

/// Two lists of numbers, one after the other, with bare commas.
pub(super) fn join(first: &[u32], second: &[u32]) -> String {
    let items: Vec<String> = first.iter().chain(second).map(u32::to_string).collect();
    items.join(",")
}

/// mavlink-router's address check: four dotted groups of 1-3 digits, or an IPv6 address in
/// brackets. Hostnames are not accepted.
pub(super) fn check_address(value: &str) -> Result<(), &'static str> {
    if let Some(inner) = value.strip_prefix('[').and_then(|v| v.strip_suffix(']')) {
        return match inner.parse::<Ipv6Addr>() {
            Ok(_) => Ok(()),
            Err(_) => Err("is not an IPv6 address"),
        };
    }
    let dotted = value.split('.').count() == 4
        && value
            .split('.')
            .all(|g| (1..=3).contains(&g.len()) && g.bytes().all(|b| b.is_ascii_digit()));
    if dotted && value.parse::<Ipv4Addr>().is_ok() {
        Ok(())
    } else if value.parse::<Ipv6Addr>().is_ok() {
        Err("is an IPv6 address without brackets; write it as [ADDRESS]")
    } else {
        Err("is not an IPv4 address or an IPv6 address in brackets")
    }
}

/// The choice `value` names, ignoring ASCII case.
pub(super) fn one_of(choices: &[&'static str], value: &str) -> Option<&'static str> {
    choices
        .iter()
        .find(|c| c.eq_ignore_ascii_case(value))
        .copied()
}

/// Characters a value must not hold to be a link option (or the device in `serial:DEVICE:BAUD`).
pub(super) const FORBIDDEN: [char; 4] = [',', '&', '?', '='];
