//! Byte ranges still wanted by a transfer (a MAVFTP read, a log download): `[start, end)`
//! pairs, sorted and disjoint.

use alloc::vec::Vec;

/// Removes `[s, e)` from sorted disjoint ranges.
pub(crate) fn subtract(ranges: &mut Vec<(u32, u32)>, s: u32, e: u32) {
    let mut out = Vec::with_capacity(ranges.len() + 1);
    for &(a, b) in ranges.iter() {
        if e <= a || b <= s {
            out.push((a, b));
            continue;
        }
        if a < s {
            out.push((a, s));
        }
        if e < b {
            out.push((e, b));
        }
    }
    *ranges = out;
}

/// How many bytes the ranges hold.
pub(crate) fn total(ranges: &[(u32, u32)]) -> u64 {
    ranges.iter().map(|&(a, b)| u64::from(b - a)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subtracting_splits_trims_and_drops() {
        let mut r = alloc::vec![(0, 10), (20, 30)];
        subtract(&mut r, 5, 7);
        assert_eq!(r, [(0, 5), (7, 10), (20, 30)]);
        subtract(&mut r, 8, 25);
        assert_eq!(r, [(0, 5), (7, 8), (25, 30)]);
        subtract(&mut r, 0, u32::MAX);
        assert!(r.is_empty());
        assert_eq!(total(&[(0, 5), (7, 8)]), 6);
    }
}
