//! Learned routes: which links lead to each (system, component).
//!
//! Every accepted frame teaches the router that its source is reachable through the link it
//! came in on. A source heard on a second link *moves* there only when its old link has
//! been quiet for [`RouterConfig::route_move_after`](crate::RouterConfig::route_move_after);
//! while both are fresh, both lead to it. That keeps redundant links working, and it is
//! why an echo of a vehicle's frame on another link cannot cut the vehicle off (the
//! mavlink-router #452 case): the vehicle's own link stays fresh. Routes not refreshed for
//! the route TTL are forgotten.

use alloc::collections::BTreeMap;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;

use crate::router::LinkId;

/// How many links one source can be reachable through at once.
pub const MAX_PATHS: usize = 4;

#[derive(Clone, Copy, Debug)]
struct Path {
    link: LinkId,
    last_seen: Instant,
}

/// A source's paths, the freshest first.
#[derive(Clone, Debug, Default)]
struct Paths {
    paths: [Option<Path>; MAX_PATHS],
}

impl Paths {
    fn iter(&self) -> impl Iterator<Item = &Path> {
        self.paths.iter().flatten()
    }
}

/// One route as reported by [`Routes::iter`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Route {
    /// System id of the source.
    pub sysid: u8,
    /// Component id of the source.
    pub compid: u8,
    /// A link it is reachable through.
    pub link: LinkId,
    /// When it was last heard there.
    pub last_seen: Instant,
}

/// The route table.
#[derive(Clone, Debug, Default)]
pub struct Routes {
    entries: BTreeMap<(u8, u8), Paths>,
}

impl Routes {
    /// Records that `(sysid, compid)` was heard on `link` at `now`.
    pub fn learn(&mut self, now: Instant, source: (u8, u8), link: LinkId, move_after: Duration) {
        let entry = self.entries.entry(source).or_default();
        if let Some(p) = entry.paths.iter_mut().flatten().find(|p| p.link == link) {
            p.last_seen = now;
            return;
        }
        // A new link: the others stay only while they are fresh.
        for slot in &mut entry.paths {
            if slot.is_some_and(|p| now.saturating_duration_since(p.last_seen) >= move_after) {
                *slot = None;
            }
        }
        let new = Path {
            link,
            last_seen: now,
        };
        if let Some(slot) = entry.paths.iter_mut().find(|s| s.is_none()) {
            *slot = Some(new);
        } else if let Some(oldest) = entry
            .paths
            .iter_mut()
            .min_by_key(|s| s.map_or(Instant::ZERO, |p| p.last_seen))
        {
            *oldest = Some(new);
        }
    }

    /// Appends to `out` every link through which `(sysid, compid)` was heard within `ttl`;
    /// with `compid` 0, or a component never heard, the links of any component of the system.
    /// Returns whether the target is known at all (heard within `ttl` on any link).
    pub fn links_to(
        &self,
        now: Instant,
        ttl: Duration,
        sysid: u8,
        compid: u8,
        out: &mut Vec<LinkId>,
    ) -> bool {
        let fresh = |p: &&Path| now.saturating_duration_since(p.last_seen) < ttl;
        let mut push = |paths: &Paths| {
            let mut any = false;
            for p in paths.iter().filter(fresh) {
                any = true;
                if !out.contains(&p.link) {
                    out.push(p.link);
                }
            }
            any
        };
        if compid != 0
            && let Some(paths) = self.entries.get(&(sysid, compid))
            && push(paths)
        {
            return true;
        }
        let mut any = false;
        for (_, paths) in self.entries.range((sysid, 0)..=(sysid, u8::MAX)) {
            any |= push(paths);
        }
        any
    }

    /// Forgets paths not refreshed within `ttl`.
    pub fn expire(&mut self, now: Instant, ttl: Duration) {
        self.entries.retain(|_, paths| {
            for slot in &mut paths.paths {
                if slot.is_some_and(|p| now.saturating_duration_since(p.last_seen) >= ttl) {
                    *slot = None;
                }
            }
            paths.iter().next().is_some()
        });
    }

    /// Forgets every path through `link`.
    pub fn remove_link(&mut self, link: LinkId) {
        self.entries.retain(|_, paths| {
            for slot in &mut paths.paths {
                if slot.is_some_and(|p| p.link == link) {
                    *slot = None;
                }
            }
            paths.iter().next().is_some()
        });
    }

    /// Every route, by source.
    pub fn iter(&self) -> impl Iterator<Item = Route> + '_ {
        self.entries.iter().flat_map(|(&(sysid, compid), paths)| {
            paths.iter().map(move |p| Route {
                sysid,
                compid,
                link: p.link,
                last_seen: p.last_seen,
            })
        })
    }

    /// How many sources are known.
    #[must_use]
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether no source is known.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TTL: Duration = Duration::from_secs(30);
    const MOVE: Duration = Duration::from_secs(1);

    fn to(r: &Routes, now: Instant, sys: u8, comp: u8) -> (bool, Vec<LinkId>) {
        let mut v = Vec::new();
        let known = r.links_to(now, TTL, sys, comp, &mut v);
        (known, v)
    }

    #[test]
    fn echo_does_not_cut_a_system_off_but_a_move_does() {
        let (a, b) = (LinkId::new(0), LinkId::new(1));
        let mut r = Routes::default();
        let t = Instant::from_secs(100);
        r.learn(t, (1, 1), a, MOVE);
        // An echo on b a moment later: both lead to it.
        r.learn(t + Duration::from_millis(10), (1, 1), b, MOVE);
        assert_eq!(to(&r, t, 1, 1).1, [a, b]);
        // The vehicle keeps talking on a; b's echo is not refreshed and expires.
        let mut now = t;
        for _ in 0..40 {
            now += Duration::from_secs(1);
            r.learn(now, (1, 1), a, MOVE);
        }
        r.expire(now, TTL);
        assert_eq!(to(&r, now, 1, 1).1, [a]);
        // The vehicle goes quiet on a and shows up on b 5 s later: it moved.
        r.learn(now + Duration::from_secs(5), (1, 1), b, MOVE);
        assert_eq!(to(&r, now + Duration::from_secs(5), 1, 1).1, [b]);
    }

    #[test]
    fn component_falls_back_to_system_and_unknown_is_unknown() {
        let (a, b) = (LinkId::new(0), LinkId::new(1));
        let mut r = Routes::default();
        let t = Instant::from_secs(5);
        r.learn(t, (1, 1), a, MOVE);
        r.learn(t, (1, 100), b, MOVE);
        assert_eq!(to(&r, t, 1, 100), (true, alloc::vec![b]));
        assert_eq!(to(&r, t, 1, 0), (true, alloc::vec![a, b]));
        assert_eq!(to(&r, t, 1, 42), (true, alloc::vec![a, b]));
        assert_eq!(to(&r, t, 2, 1), (false, alloc::vec![]));
        assert_eq!(to(&r, t + TTL, 1, 1), (false, alloc::vec![]));
        r.remove_link(a);
        assert_eq!(to(&r, t, 1, 1), (true, alloc::vec![b]));
        r.expire(t + TTL, TTL);
        assert!(r.is_empty());
    }
}
