//! The parameter protocol in both roles, unit by unit and through the simulated link.

mod util;

use core::time::Duration;

use mavstack_dialects::common::{MavMessage, MavParamType, ParamRequestRead, ParamSet};
use mavstack_services::param::{
    Encoding, Name, Param, ParamClient, ParamConfig, ParamError, ParamEvent, ParamHandle, ParamRef,
    ParamRequestError, ParamServer, ParamServerEvent, Value, list::ListFetch,
};
use mavstack_services::{Address, Outgoing, Service};
use util::{Knobs, Pair, T0};

const GCS: Address = Address::new(255, 190);
const VEHICLE: Address = Address::new(1, 1);

fn name(s: &str) -> Name {
    Name::new(s).unwrap()
}

/// A table of `n` parameters of every type, with values that C-cast carries exactly.
fn table(n: usize, encoding: Encoding) -> ParamServer {
    let mut s = ParamServer::new(VEHICLE, encoding);
    for i in 0..n {
        let k = i as i32;
        let v = match i % 7 {
            0 => Value::U8((k % 256) as u8),
            1 => Value::I8((k % 100 - 50) as i8),
            2 => Value::U16((k * 7 % 65_536) as u16),
            3 => Value::I16((k - 500) as i16),
            4 => Value::U32(k as u32 * 1_001),
            5 => Value::I32(-k * 999),
            _ => Value::F32(k as f32 * 0.25 - 3.5),
        };
        s.insert(name(&format!("PARAM_{i:05}")), v).unwrap();
    }
    s
}

type Sim = Pair<ParamClient, ParamServer>;

fn sim(server: ParamServer, encoding: Encoding, knobs: Knobs, seed: u64) -> Sim {
    Pair::new(
        ParamClient::new(ParamConfig::default(), encoding),
        GCS,
        server,
        VEHICLE,
        knobs,
        seed,
    )
}

fn finished(c: &mut ParamClient) -> Vec<(ParamHandle, Result<Param, ParamError>)> {
    core::iter::from_fn(|| c.poll_event())
        .filter_map(|e| match e {
            ParamEvent::Finished { handle, result } => Some((handle, result)),
            _ => None,
        })
        .collect()
}

/// Fetches the whole list; returns it with the virtual time and messages it took.
type ListResult = Result<Vec<(Name, Value)>, ParamError>;

/// A client (`config`) that asked a table of `n` values for its list, and what the table
/// sent in answer.
fn list_asked(config: ParamConfig, n: usize) -> (ParamClient, Vec<Outgoing>) {
    let mut c = ParamClient::new(config, Encoding::Bytewise);
    let mut s = table(n, Encoding::Bytewise);
    c.fetch_all(T0, VEHICLE).unwrap();
    let req = c.poll_transmit().unwrap();
    s.handle_message(T0, GCS, &req.message);
    (c, core::iter::from_fn(|| s.poll_transmit()).collect())
}

/// The client's next event is the whole list, `count` values.
fn assert_listed(c: &mut ParamClient, count: usize) {
    match c.poll_event() {
        Some(ParamEvent::List {
            result: Ok(list), ..
        }) => assert_eq!(list.len(), count),
        other => panic!("{other:?}"),
    }
}

fn fetch(p: &mut Sim) -> (ListResult, Duration, u64) {
    let start = p.now;
    let m0 = p.messages();
    p.a.fetch_all(p.now, VEHICLE).unwrap();
    let mut result = None;
    assert!(p.drive_until(Duration::from_secs(120), |c, _, _| {
        while let Some(e) = c.poll_event() {
            if let ParamEvent::List { target, result: r } = e {
                assert_eq!(target, VEHICLE);
                result = Some(r);
            }
        }
        result.is_some()
    }));
    (result.unwrap(), p.now - start, p.messages() - m0)
}

fn check_fetch(n: usize, encoding: Encoding, knobs: Knobs, seed: u64) -> (Duration, u64) {
    let mut p = sim(table(n, encoding), encoding, knobs, seed);
    let (result, took, messages) = fetch(&mut p);
    let got = result.unwrap();
    let want: Vec<(Name, Value)> = p.b.iter().copied().collect();
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(&want) {
        assert_eq!(g.0, w.0);
        assert!(g.1.same_as(w.1), "{:?}: {:?} != {:?}", g.0, g.1, w.1);
    }
    assert!(p.a.list_state(VEHICLE).is_none());
    (took, messages)
}

#[test]
fn sim_fetch_1000_params_clean_and_under_loss() {
    let (t, m) = check_fetch(1000, Encoding::Bytewise, Knobs::clean(), 1);
    eprintln!("fetch 1000 params, clean link: {t:?} virtual, {m} messages");
    assert_eq!(m, 1001);
    assert!(t < Duration::from_millis(50));
    for seed in [1, 2, 3, 4] {
        let (t, m) = check_fetch(1000, Encoding::Bytewise, Knobs::hostile(), seed);
        eprintln!(
            "fetch 1000 params, 20% loss + 20% dup + jitter (seed {seed}): {t:?} virtual, {m} messages"
        );
        assert!(t < Duration::from_secs(10), "{t:?}");
    }
}

#[test]
fn sim_fetch_with_c_cast_like_ardupilot() {
    check_fetch(200, Encoding::CCast, Knobs::hostile(), 9);
}

#[test]
fn list_fetch_phases_are_types() {
    let mut c = ParamClient::new(ParamConfig::default(), Encoding::Bytewise);
    let mut s = table(10, Encoding::Bytewise);
    c.fetch_all(T0, VEHICLE).unwrap();
    assert_eq!(
        c.fetch_all(T0, VEHICLE),
        Err(ParamRequestError::ListBusy { target: VEHICLE })
    );
    assert!(matches!(
        c.list_state(VEHICLE),
        Some(ListFetch::AwaitingCount(_))
    ));
    let req = c.poll_transmit().unwrap();
    assert!(
        matches!(req.message, MavMessage::ParamRequestList(m) if (m.target_system, m.target_component) == (1, 1))
    );
    s.handle_message(T0, GCS, &req.message);
    let values: Vec<_> = core::iter::from_fn(|| s.poll_transmit()).collect();
    assert_eq!(values.len(), 10);
    // Lose indices 3 and 7.
    for (i, v) in values.iter().enumerate() {
        if i != 3 && i != 7 {
            c.handle_message(T0, VEHICLE, &v.message);
        }
    }
    let Some(ListFetch::Collecting(col)) = c.list_state(VEHICLE) else {
        panic!()
    };
    assert_eq!((col.count(), col.missing()), (10, 2));
    // The inactivity timer re-requests exactly the gaps, by index. It adapts to the
    // stream: a burst with no gaps (the last index came) gives the 20 ms floor, not the 2 s
    // ceiling.
    let t = c.poll_timeout().unwrap();
    assert_eq!(t, T0 + Duration::from_millis(20));
    c.handle_timeout(t);
    let asks: Vec<i16> = core::iter::from_fn(|| c.poll_transmit())
        .map(|o| match o.message {
            MavMessage::ParamRequestRead(r) => r.param_index,
            _ => panic!(),
        })
        .collect();
    assert_eq!(asks, [3, 7]);
    for i in [3, 7] {
        c.handle_message(t, VEHICLE, &values[i].message);
    }
    assert_listed(&mut c, 10);
}

/// Each re-request has its own wait: answers to the others (the window sliding on) do not
/// hold back the resend of one the vehicle dropped (ArduPilot drops a PARAM_REQUEST_READ
/// that does not fit its queue of 20).
#[test]
fn a_dropped_re_request_is_sent_again_while_the_others_are_answered() {
    let config = ParamConfig {
        rerequest_batch: 3,
        ..ParamConfig::default()
    };
    let (mut c, values) = list_asked(config, 10);
    for (i, v) in values.iter().enumerate() {
        if !(1..=6).contains(&i) {
            c.handle_message(T0, VEHICLE, &v.message);
        }
    }
    let asked = |c: &mut ParamClient| -> Vec<i16> {
        core::iter::from_fn(|| c.poll_transmit())
            .map(|o| match o.message {
                MavMessage::ParamRequestRead(r) => r.param_index,
                other => panic!("{other:?}"),
            })
            .collect()
    };
    let t = c.poll_timeout().unwrap();
    c.handle_timeout(t);
    assert_eq!(asked(&mut c), [1, 2, 3]);
    let lost_at = c.poll_timeout().unwrap();
    // 1 is answered (2 and 3 were dropped): 4 takes its place, and 2 and 3 keep their wait.
    c.handle_message(t + Duration::from_millis(5), VEHICLE, &values[1].message);
    assert_eq!(asked(&mut c), [4]);
    assert_eq!(c.poll_timeout(), Some(lost_at));
    c.handle_timeout(lost_at);
    assert_eq!(asked(&mut c), [2, 3]);
}

#[test]
fn a_component_without_parameters_times_out() {
    let mut p = sim(
        ParamServer::new(VEHICLE, Encoding::Bytewise),
        Encoding::Bytewise,
        Knobs::clean(),
        1,
    );
    let (result, took, messages) = fetch(&mut p);
    assert_eq!(result, Err(ParamError::TimedOut { attempts: 6 }));
    assert_eq!(messages, 6);
    assert_eq!(took, Duration::from_secs(3));
}

#[test]
fn sim_set_confirms_under_loss_and_keeps_types() {
    for (encoding, seed) in [(Encoding::Bytewise, 5), (Encoding::CCast, 6)] {
        let mut p = sim(table(50, encoding), encoding, Knobs::hostile(), seed);
        let mut ok = 0;
        for i in 0..50usize {
            let n = name(&format!("PARAM_{i:05}"));
            let stored = p.b.get(n).unwrap();
            // Ask for a float; the server keeps the parameter's own type.
            let want = Value::F32(i as f32 + 1.0)
                .converted_to(stored.param_type())
                .unwrap();
            let h =
                p.a.set(p.now, VEHICLE, n, Value::F32(i as f32 + 1.0))
                    .unwrap();
            let mut result = None;
            assert!(p.drive_until(Duration::from_secs(10), |c, _, _| {
                for (hh, r) in finished(c) {
                    if hh == h {
                        result = Some(r);
                    }
                }
                result.is_some()
            }));
            let got = result.unwrap().unwrap();
            assert!(got.value.same_as(want), "{got:?} vs {want:?}");
            assert_eq!(got.value.param_type(), stored.param_type());
            assert!(p.b.get(n).unwrap().same_as(want));
            ok += 1;
            p.drive_for(Duration::from_millis(100));
        }
        assert_eq!(ok, 50);
    }
}

#[test]
fn sim_read_by_name_and_index_under_loss() {
    let mut p = sim(
        table(30, Encoding::Bytewise),
        Encoding::Bytewise,
        Knobs::hostile(),
        11,
    );
    let by_name =
        p.a.read(p.now, VEHICLE, ParamRef::Name(name("PARAM_00012")));
    let by_index = p.a.read(p.now, VEHICLE, ParamRef::Index(20));
    let mut results = vec![];
    assert!(p.drive_until(Duration::from_secs(10), |c, _, _| {
        results.extend(finished(c));
        results.len() == 2
    }));
    results.sort_by_key(|r| r.0);
    assert_eq!((results[0].0, results[1].0), (by_name, by_index));
    let a = results[0].1.unwrap();
    assert_eq!((a.name, a.index, a.count), (name("PARAM_00012"), 12, 30));
    let b = results[1].1.unwrap();
    assert_eq!((b.name, b.index), (name("PARAM_00020"), 20));
    assert!(b.value.same_as(p.b.get(name("PARAM_00020")).unwrap()));
}

#[test]
fn unknown_names_get_no_answer_and_time_out() {
    let mut p = sim(
        table(3, Encoding::Bytewise),
        Encoding::Bytewise,
        Knobs::clean(),
        1,
    );
    let h =
        p.a.set(p.now, VEHICLE, name("NO_SUCH"), Value::I32(1))
            .unwrap();
    let r = p.a.read(p.now, VEHICLE, ParamRef::Index(99));
    let mut results = vec![];
    p.drive_until(Duration::from_secs(10), |c, _, _| {
        results.extend(finished(c));
        results.len() == 2
    });
    assert_eq!(
        results,
        [
            (h, Err(ParamError::TimedOut { attempts: 6 })),
            (r, Err(ParamError::TimedOut { attempts: 6 }))
        ]
    );
    let events: Vec<_> = core::iter::from_fn(|| p.b.poll_event()).collect();
    assert_eq!(events.len(), 12);
    assert_eq!(
        events[0],
        ParamServerEvent::Unknown {
            from: GCS,
            name: Some(name("NO_SUCH"))
        }
    );
    assert_eq!(
        events[1],
        ParamServerEvent::Unknown {
            from: GCS,
            name: None
        }
    );
}

#[test]
fn a_set_the_target_refuses_ends_rejected() {
    let mut c = ParamClient::new(ParamConfig::default(), Encoding::Bytewise);
    let n = name("ARMING_CHECK");
    let h = c.set(T0, VEHICLE, n, Value::I32(0)).unwrap();
    assert_eq!(
        c.set(T0, VEHICLE, n, Value::I32(0)),
        Err(ParamRequestError::SetBusy {
            target: VEHICLE,
            name: n
        })
    );
    let echo = MavMessage::ParamValue(mavstack_dialects::common::ParamValue {
        param_id: n.to_field(),
        param_value: Encoding::Bytewise.encode(Value::I32(1)),
        param_type: MavParamType::INT32,
        param_count: 1,
        param_index: 0,
    });
    let mut sets = 0;
    for _ in 0..10 {
        sets += core::iter::from_fn(|| c.poll_transmit())
            .filter(|o| matches!(o.message, MavMessage::ParamSet(ParamSet { param_value, .. }) if param_value.to_bits() == 0))
            .count();
        c.handle_message(T0, VEHICLE, &echo);
    }
    assert_eq!(sets, 6);
    assert_eq!(
        finished(&mut c),
        [(
            h,
            Err(ParamError::Rejected {
                value: Value::I32(1)
            })
        )]
    );
}

#[test]
fn server_answers_reads_by_name_and_broadcasts_sets() {
    let mut s = table(5, Encoding::CCast);
    let read = ParamRequestRead {
        target_system: 1,
        target_component: 1,
        param_id: name("PARAM_00003").to_field(),
        param_index: -1,
    };
    assert!(s.handle_message(T0, GCS, &MavMessage::ParamRequestRead(read)));
    let out = s.poll_transmit().unwrap();
    assert_eq!(out.target, GCS);
    let MavMessage::ParamValue(v) = out.message else {
        panic!()
    };
    assert_eq!(
        (v.param_index, v.param_count, v.param_type),
        (3, 5, MavParamType::INT16)
    );
    assert_eq!(v.param_value, -497.0);
    // Not for us.
    assert!(!s.handle_message(
        T0,
        GCS,
        &MavMessage::ParamRequestRead(ParamRequestRead {
            target_system: 2,
            ..read
        })
    ));
    // A set: converted to the stored type (INT16, rounded), broadcast, reported.
    let set = ParamSet {
        target_system: 1,
        target_component: 1,
        param_id: name("PARAM_00003").to_field(),
        param_value: 12.6,
        param_type: MavParamType::REAL32,
    };
    s.handle_message(T0, GCS, &MavMessage::ParamSet(set));
    let out = s.poll_transmit().unwrap();
    assert_eq!(out.target, Address::BROADCAST);
    assert_eq!(s.get(name("PARAM_00003")), Some(Value::I16(13)));
    assert_eq!(
        s.poll_event(),
        Some(ParamServerEvent::Changed {
            from: GCS,
            name: name("PARAM_00003"),
            value: Value::I16(13)
        })
    );
    // A local change is broadcast too, and unsolicited values reach the client as events.
    assert_eq!(
        s.set(name("PARAM_00000"), Value::F32(9.0)),
        Ok(Value::U8(9))
    );
    let mut c = ParamClient::new(ParamConfig::default(), Encoding::CCast);
    c.handle_message(T0, VEHICLE, &s.poll_transmit().unwrap().message);
    assert!(
        matches!(c.poll_event(), Some(ParamEvent::Value { from: VEHICLE, param }) if param.value == Value::U8(9))
    );
}

/// ArduPilot keeps at most 16 re-requests out (its queue holds 20, shared by its links);
/// other autopilots keep the configured window.
#[test]
fn the_re_request_window_fits_the_autopilot() {
    use mavstack_dialects::common::MavAutopilot;
    let config = ParamConfig::default();
    assert_eq!(
        config
            .for_autopilot(MavAutopilot::ARDUPILOTMEGA)
            .rerequest_batch,
        16
    );
    assert_eq!(config.for_autopilot(MavAutopilot::PX4), config);
    let small = ParamConfig {
        rerequest_batch: 4,
        ..config
    };
    assert_eq!(
        small
            .for_autopilot(MavAutopilot::ARDUPILOTMEGA)
            .rerequest_batch,
        4
    );
}

/// A stream that pauses does not end the fetch early: each round without a new value lasts
/// at least `ParamConfig::timeout`, however short the measured round trip (here 1 ms, as
/// when gap requests are answered at once by the stream itself), so six of them take 3 s.
#[test]
fn a_pause_in_a_fast_stream_does_not_end_the_fetch() {
    let (mut c, values) = list_asked(ParamConfig::default(), 40);
    let t1 = T0 + Duration::from_millis(1);
    for v in &values[..10] {
        c.handle_message(t1, VEHICLE, &v.message);
    }
    // Nothing more for 2 s: the client asks for the gaps, round after round.
    let mut now = t1;
    while let Some(t) = c.poll_timeout() {
        if t > t1 + Duration::from_secs(2) {
            break;
        }
        now = t;
        c.handle_timeout(now);
        while c.poll_transmit().is_some() {}
        assert!(c.poll_event().is_none(), "gave up at {:?}", now - t1);
    }
    // The rest comes: the table is whole.
    for v in &values[10..] {
        c.handle_message(now, VEHICLE, &v.message);
    }
    assert_listed(&mut c, 40);
}

/// The PARAM_REQUEST_READs `c` has queued, by index.
fn re_requests(c: &mut ParamClient) -> Vec<u16> {
    core::iter::from_fn(|| c.poll_transmit())
        .map(|o| match o.message {
            MavMessage::ParamRequestRead(r) => r.param_index.unsigned_abs(),
            other => panic!("{other:?}"),
        })
        .collect()
}

/// ArduPilot sends the first value of its list alone and the rest about 100 ms later. That
/// pause is no gap of the stream: with nothing to compare it to, the fetch waits as long as
/// before any value. (The first value counted as a gap of zero, so the fetch asked for the
/// whole table by index 20 ms after it; through the relay ArduPilot then answered those
/// requests instead of streaming, 50 values a second, and the table took 62 s.)
#[test]
fn the_pause_after_the_first_value_does_not_start_the_re_requests() {
    let (mut c, values) = list_asked(ParamConfig::default(), 40);
    let first = T0 + Duration::from_millis(200);
    c.handle_message(first, VEHICLE, &values[0].message);
    let rest = first + Duration::from_millis(100);
    while let Some(t) = c.poll_timeout().filter(|&t| t < rest) {
        c.handle_timeout(t);
        let asked = re_requests(&mut c);
        assert!(
            asked.is_empty(),
            "asked for {asked:?} {:?} after the first value",
            t - first
        );
    }
    for v in &values[1..] {
        c.handle_message(rest, VEHICLE, &v.message);
    }
    assert_listed(&mut c, 40);
}

/// A re-request of an index the stream has not reached yet may be answered by the stream
/// itself, at once: such an answer says nothing of the round trip. (Taken as samples, they
/// brought the wait of every re-request to its 20 ms floor on a 200 ms link, and the client
/// resent its whole window every 20 ms: 47,000 requests in a 62 s fetch from ArduPilot.)
#[test]
fn a_re_request_the_stream_answers_is_no_round_trip_sample() {
    let (mut c, values) = list_asked(ParamConfig::default(), 100);
    // The round trip is 200 ms; the stream comes in two bursts with a pause between.
    let t1 = T0 + Duration::from_millis(200);
    for v in &values[..10] {
        c.handle_message(t1, VEHICLE, &v.message);
    }
    let asked_at = c.poll_timeout().unwrap();
    c.handle_timeout(asked_at);
    let ahead = re_requests(&mut c);
    assert!(ahead.first() == Some(&10), "{ahead:?}");
    // The second burst answers those re-requests 1 ms after they went; then the stream
    // ends (the last 30 values are lost).
    let t2 = asked_at + Duration::from_millis(1);
    for v in &values[10..70] {
        c.handle_message(t2, VEHICLE, &v.message);
    }
    let mut sent: std::collections::BTreeMap<u16, mavstack_core::time::Instant> =
        re_requests(&mut c).into_iter().map(|i| (i, t2)).collect();
    for i in ahead.into_iter().filter(|i| *i >= 70) {
        sent.insert(i, asked_at);
    }
    // Nothing more comes: no re-request is sent again before a round trip has passed.
    let end = t2 + Duration::from_secs(1);
    while let Some(t) = c.poll_timeout().filter(|&t| t < end) {
        c.handle_timeout(t);
        for i in re_requests(&mut c) {
            if let Some(before) = sent.insert(i, t) {
                assert!(
                    t - before >= Duration::from_millis(200),
                    "{i} sent again after {:?}",
                    t - before
                );
            }
        }
    }
}

/// What `c` transmits next, once its timer runs out: its messages, and when.
fn after_the_stream(c: &mut ParamClient) -> (mavstack_core::time::Instant, Vec<MavMessage>) {
    let t = c.poll_timeout().unwrap();
    c.handle_timeout(t);
    (
        t,
        core::iter::from_fn(|| c.poll_transmit())
            .map(|o| o.message)
            .collect(),
    )
}

/// Feeds `c` the values of `values` that `keep` lets through, `gap` apart from `start`;
/// returns when the last one came.
fn stream(
    c: &mut ParamClient,
    values: &[Outgoing],
    start: mavstack_core::time::Instant,
    gap: Duration,
    keep: impl Fn(usize) -> bool,
) -> mavstack_core::time::Instant {
    let mut t = start;
    for (i, v) in values.iter().enumerate() {
        t += gap;
        if keep(i) {
            c.handle_message(t, VEHICLE, &v.message);
        }
    }
    t
}

/// A client (16 re-requests at most, as for ArduPilot) that got a table of 1,000 values a
/// round trip of 200 ms after asking, one every `gap`, every fourth lost, and asked for the
/// whole list again when its timer ran out (at the instant returned).
fn listed_again(gap: Duration) -> (ParamClient, Vec<Outgoing>, mavstack_core::time::Instant) {
    let config = ParamConfig {
        rerequest_batch: 16,
        ..ParamConfig::default()
    };
    let (mut c, values) = list_asked(config, 1000);
    let first = T0 + Duration::from_millis(200);
    stream(&mut c, &values, first, gap, |i| i % 4 != 1);
    let (t, asked) = after_the_stream(&mut c);
    assert!(
        matches!(asked.as_slice(), [MavMessage::ParamRequestList(_)]),
        "{asked:?}"
    );
    (c, values, t)
}

/// A fast stream that lost a quarter of its values: the table streams again in half a
/// second, where 250 values one by one, 16 at a time, would take three. The client asks for
/// the whole list again, then for the last gaps one by one.
#[test]
fn a_fast_lossy_stream_is_asked_for_again_whole() {
    let (mut c, values, t) = listed_again(Duration::from_micros(500));
    // The second pass loses one in eight of those (only the indexes ≡ 1 mod 32 are missing
    // now, 32 of them): a third pass would take 0.7 s, these one by one less than half a
    // second. They go one by one.
    let second = t + Duration::from_millis(200);
    stream(&mut c, &values, second, Duration::from_micros(500), |i| {
        i % 32 != 1
    });
    let (t, asked) = after_the_stream(&mut c);
    let indexes: Vec<u16> = asked
        .iter()
        .map(|m| match m {
            MavMessage::ParamRequestRead(r) => r.param_index.unsigned_abs(),
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(indexes, (0..16).map(|k| 1 + 32 * k).collect::<Vec<u16>>());
    // They are answered: the table is whole.
    let mut now = t + Duration::from_millis(200);
    loop {
        for v in values.iter().skip(1).step_by(32) {
            c.handle_message(now, VEHICLE, &v.message);
        }
        if let Some(ParamEvent::List { result, .. }) = c.poll_event() {
            assert_eq!(result.unwrap().len(), 1000);
            break;
        }
        while c.poll_transmit().is_some() {}
        now += Duration::from_millis(200);
        assert!(now < t + Duration::from_secs(5), "not done");
    }
}

/// Every message of `asked` is a PARAM_REQUEST_READ (the gaps go one by one).
fn assert_reads_only(asked: &[MavMessage]) {
    assert!(
        asked
            .iter()
            .all(|m| matches!(m, MavMessage::ParamRequestRead(_))),
        "{asked:?}"
    );
}

/// A telemetry radio: the table takes two seconds to stream and 5 % of it is lost. The
/// gaps go one by one; a second pass would cost more than they do.
#[test]
fn a_slow_stream_has_its_gaps_asked_for_one_by_one() {
    let (mut c, values) = list_asked(ParamConfig::default(), 200);
    let first = T0 + Duration::from_millis(100);
    stream(&mut c, &values, first, Duration::from_millis(10), |i| {
        i % 20 != 7
    });
    let (_, asked) = after_the_stream(&mut c);
    assert_eq!(asked.len(), 10, "{asked:?}");
    assert_reads_only(&asked);
}

/// A fast, lossy stream that stopped half-way (the vehicle was busy, a relay paused): it
/// says nothing of what a second pass would bring, so the gaps go one by one.
#[test]
fn a_stream_cut_short_is_not_asked_for_again() {
    let (mut c, values) = list_asked(ParamConfig::default(), 1000);
    let first = T0 + Duration::from_millis(200);
    stream(
        &mut c,
        &values[..500],
        first,
        Duration::from_micros(500),
        |i| i % 4 != 1,
    );
    let (_, asked) = after_the_stream(&mut c);
    assert!(!asked.is_empty());
    assert_reads_only(&asked);
}

/// The second pass of the stream pauses half-way (a vehicle sends its table in bursts):
/// that the last index came in the first pass does not make the pause its end.
#[test]
fn a_pause_in_a_second_pass_does_not_end_it() {
    let (mut c, values, t) = listed_again(Duration::from_millis(1));
    let half = stream(
        &mut c,
        &values[..500],
        t + Duration::from_millis(200),
        Duration::from_millis(1),
        |_| true,
    );
    // 32 of the stream's 1 ms gaps, not the 20 ms floor of a stream that has ended.
    let wait = c.poll_timeout().unwrap() - half;
    assert!(wait >= Duration::from_millis(30), "{wait:?}");
}
