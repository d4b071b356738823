//! The mission protocol in both roles, through the simulated link and unit by unit.

mod util;

use core::time::Duration;

use mavstack_dialects::common::{
    MavCmd, MavFrame, MavMessage, MavMissionResult, MavMissionType, MissionCount, MissionItemInt,
    MissionRequestInt,
};
use mavstack_services::mission::{
    MissionClient, MissionConfig, MissionError, MissionEvent, MissionServer, MissionServerEvent,
    transfer::{Download, Upload},
};
use mavstack_services::{Address, Service};
use util::{Knobs, Pair, T0};

const GCS: Address = Address::new(255, 190);
const VEHICLE: Address = Address::new(1, 1);

fn items(n: usize) -> Vec<MissionItemInt> {
    (0..n)
        .map(|i| MissionItemInt {
            frame: MavFrame::GLOBAL_RELATIVE_ALT_INT,
            command: MavCmd::NAV_WAYPOINT,
            autocontinue: 1,
            x: 473_977_418 + i as i32 * 100,
            y: 85_455_939 - i as i32 * 50,
            z: 20.0 + i as f32,
            param1: i as f32,
            ..Default::default()
        })
        .collect()
}

type Sim = Pair<MissionClient, MissionServer>;

/// The default config (5 retries) on a clean link; 10 retries on a lossy one: at 20 % loss
/// each way a request/item round trip fails with p = 0.36, so 6 tries of one item all
/// fail with p = 0.36^6 ≈ 0.2 %, and a 500-item download with the default would fail
/// about two times in three. With 11 tries: 1.3e-5 per item.
fn config(knobs: Knobs) -> MissionConfig {
    if knobs.loss > 0.0 {
        MissionConfig {
            retries: 10,
            ..MissionConfig::default()
        }
    } else {
        MissionConfig::default()
    }
}

fn sim(knobs: Knobs, seed: u64) -> Sim {
    Pair::new(
        MissionClient::new(GCS, config(knobs)),
        GCS,
        MissionServer::new(VEHICLE, config(knobs)),
        VEHICLE,
        knobs,
        seed,
    )
}

/// Drives until the client reports; returns the event, virtual time and messages.
fn wait(p: &mut Sim) -> (MissionEvent, Duration, u64) {
    let (t0, m0) = (p.now, p.messages());
    let mut event = None;
    assert!(p.drive_until(Duration::from_secs(600), |c, _, _| {
        if event.is_none() {
            event = c.poll_event();
        }
        event.is_some()
    }));
    // Let the last messages land (a final ACK, duplicates).
    p.drive_for(Duration::from_millis(100));
    (event.unwrap(), p.now - t0, p.messages() - m0)
}

fn same_items(got: &[MissionItemInt], want: &[MissionItemInt]) {
    assert_eq!(got.len(), want.len());
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert_eq!(g.seq as usize, i);
        assert_eq!(
            (g.x, g.y, g.z, g.param1, g.command, g.frame),
            (w.x, w.y, w.z, w.param1, w.command, w.frame)
        );
    }
}

fn upload_then_download(knobs: Knobs, seed: u64, n: usize, ty: MavMissionType) {
    let mut p = sim(knobs, seed);
    let plan = items(n);
    p.a.upload(p.now, VEHICLE, ty, plan.clone()).unwrap();
    let (e, up_t, up_m) = wait(&mut p);
    assert_eq!(
        e,
        MissionEvent::Uploaded {
            mission_type: ty,
            result: Ok(())
        }
    );
    same_items(p.b.plan(ty), &plan);
    p.a.download(p.now, VEHICLE, ty).unwrap();
    let (e, down_t, down_m) = wait(&mut p);
    let MissionEvent::Downloaded {
        mission_type,
        result: Ok(got),
    } = e
    else {
        panic!("{e:?}")
    };
    assert_eq!(mission_type, ty);
    same_items(&got, &plan);
    eprintln!(
        "{n}-item {ty:?} (loss {}, seed {seed}): upload {up_t:?} / {up_m} messages, download {down_t:?} / {down_m} messages",
        knobs.loss
    );
}

/// Against a server answering as ArduPilot does (MISSION_ACK INVALID_SEQUENCE for an item
/// it did not ask for, the upload left open; MAV_MISSION_ERROR to an item after the upload),
/// uploads through loss, duplication and reordering store every item in place, and end
/// `Ok`, or `Unconfirmed` when the final ACK was lost (then `System` reads the plan back).
#[test]
fn sim_uploads_complete_against_a_server_that_acks_invalid_sequence() {
    use mavstack_services::mission::StrayItems;
    let mut unconfirmed = 0;
    for seed in 1..=12 {
        let knobs = Knobs::hostile();
        let server_config = MissionConfig {
            stray_items: StrayItems::ArduPilot,
            ..config(knobs)
        };
        let mut p = Pair::new(
            MissionClient::new(GCS, config(knobs)),
            GCS,
            MissionServer::new(VEHICLE, server_config),
            VEHICLE,
            knobs,
            seed,
        );
        let plan = items(200);
        p.a.upload(p.now, VEHICLE, MavMissionType::MISSION, plan.clone())
            .unwrap();
        let (e, _, _) = wait(&mut p);
        let MissionEvent::Uploaded {
            mission_type: MavMissionType::MISSION,
            result,
        } = e
        else {
            panic!("seed {seed}: {e:?}")
        };
        match result {
            Ok(()) => {}
            Err(MissionError::Unconfirmed { result }) => {
                assert_eq!(result, MavMissionResult::MAV_MISSION_ERROR);
                unconfirmed += 1;
            }
            Err(e) => panic!("seed {seed}: {e:?}"),
        }
        same_items(p.b.plan(MavMissionType::MISSION), &plan);
    }
    eprintln!("{unconfirmed} of 12 uploads ended with the final ACK lost");
}

#[test]
fn sim_500_item_mission_clean_and_under_loss() {
    upload_then_download(Knobs::clean(), 1, 500, MavMissionType::MISSION);
    for seed in [1, 2, 3] {
        upload_then_download(Knobs::hostile(), seed, 500, MavMissionType::MISSION);
    }
}

#[test]
fn sim_fence_and_rally_are_separate_plans() {
    let mut p = sim(Knobs::hostile(), 4);
    for (ty, n) in [
        (MavMissionType::MISSION, 5),
        (MavMissionType::FENCE, 7),
        (MavMissionType::RALLY, 3),
    ] {
        p.a.upload(p.now, VEHICLE, ty, items(n)).unwrap();
        assert_eq!(
            wait(&mut p).0,
            MissionEvent::Uploaded {
                mission_type: ty,
                result: Ok(())
            }
        );
    }
    assert_eq!(
        (
            p.b.plan(MavMissionType::MISSION).len(),
            p.b.plan(MavMissionType::FENCE).len(),
            p.b.plan(MavMissionType::RALLY).len()
        ),
        (5, 7, 3)
    );
    p.a.clear(p.now, VEHICLE, MavMissionType::FENCE).unwrap();
    assert_eq!(
        wait(&mut p).0,
        MissionEvent::Cleared {
            mission_type: MavMissionType::FENCE,
            result: Ok(())
        }
    );
    assert_eq!(
        (
            p.b.plan(MavMissionType::MISSION).len(),
            p.b.plan(MavMissionType::FENCE).len()
        ),
        (5, 0)
    );
    p.a.download(p.now, VEHICLE, MavMissionType::FENCE).unwrap();
    assert_eq!(
        wait(&mut p).0,
        MissionEvent::Downloaded {
            mission_type: MavMissionType::FENCE,
            result: Ok(vec![])
        }
    );
    p.a.set_current(p.now, VEHICLE, 3).unwrap();
    assert_eq!(
        wait(&mut p).0,
        MissionEvent::CurrentSet {
            seq: 3,
            result: Ok(())
        }
    );
    assert_eq!(p.b.current(), 3);
    p.a.clear(p.now, VEHICLE, MavMissionType::ALL).unwrap();
    assert_eq!(
        wait(&mut p).0,
        MissionEvent::Cleared {
            mission_type: MavMissionType::ALL,
            result: Ok(())
        }
    );
    assert!(
        p.b.plan(MavMissionType::MISSION).is_empty() && p.b.plan(MavMissionType::RALLY).is_empty()
    );
}

#[test]
fn sim_cancelled_upload_leaves_the_stored_plan_unchanged() {
    let mut p = sim(Knobs::clean(), 5);
    p.a.upload(p.now, VEHICLE, MavMissionType::MISSION, items(4))
        .unwrap();
    wait(&mut p);
    p.a.upload(p.now, VEHICLE, MavMissionType::MISSION, items(50))
        .unwrap();
    p.drive_until(Duration::from_secs(5), |c, _, _| {
        matches!(c.upload_state(), Some(Upload::AwaitingRequest(s)) if s.count() == 50) && {
            // Part-way through.
            true
        }
    });
    p.drive_for(Duration::from_millis(60));
    assert!(p.b.is_receiving());
    assert!(p.a.cancel());
    assert_eq!(
        p.a.poll_event(),
        Some(MissionEvent::Uploaded {
            mission_type: MavMissionType::MISSION,
            result: Err(MissionError::Cancelled)
        })
    );
    p.drive_for(Duration::from_secs(1));
    assert!(!p.b.is_receiving());
    assert_eq!(p.b.plan(MavMissionType::MISSION).len(), 4);
    let events: Vec<_> = core::iter::from_fn(|| p.b.poll_event()).collect();
    assert_eq!(
        events.last(),
        Some(&MissionServerEvent::UploadAbandoned {
            mission_type: MavMissionType::MISSION
        })
    );
    // The client is free again.
    assert!(!p.a.is_busy());
}

#[test]
fn sim_silent_client_makes_the_server_give_up_unchanged() {
    let mut s = MissionServer::new(VEHICLE, MissionConfig::default());
    s.handle_message(
        T0,
        GCS,
        &MavMessage::MissionCount(MissionCount {
            target_system: 1,
            target_component: 1,
            count: 3,
            mission_type: MavMissionType::MISSION,
        }),
    );
    let mut requests = 0;
    let mut gave_up = T0;
    while let Some(t) = s.poll_timeout() {
        requests += core::iter::from_fn(|| s.poll_transmit()).count();
        s.handle_timeout(t);
        gave_up = t;
    }
    // Re-requests every 250 ms (no round trip measured) until 9 s without an item:
    // ground stations like MAVProxy never resend, so the server's patience is ArduPilot's.
    assert_eq!(s.patience(), Duration::from_secs(9));
    assert_eq!(gave_up, T0 + Duration::from_secs(9));
    assert_eq!(requests, 36);
    assert_eq!(
        s.poll_event(),
        Some(MissionServerEvent::UploadAbandoned {
            mission_type: MavMissionType::MISSION
        })
    );
    assert!(s.plan(MavMissionType::MISSION).is_empty());
}

#[test]
fn no_vehicle_times_out_after_retries() {
    let mut c = MissionClient::new(GCS, MissionConfig::default());
    c.download(T0, VEHICLE, MavMissionType::MISSION).unwrap();
    assert!(matches!(
        c.download_state(),
        Some(Download::AwaitingCount(_))
    ));
    assert!(
        c.upload(T0, VEHICLE, MavMissionType::MISSION, vec![])
            .is_err()
    );
    let mut sent = 0;
    while let Some(t) = c.poll_timeout() {
        sent += core::iter::from_fn(|| c.poll_transmit()).count();
        c.handle_timeout(t);
    }
    assert_eq!(sent, 6);
    assert_eq!(
        c.poll_event(),
        Some(MissionEvent::Downloaded {
            mission_type: MavMissionType::MISSION,
            result: Err(MissionError::TimedOut { attempts: 6 })
        })
    );
}

#[test]
fn out_of_sequence_items_are_dropped_and_the_expected_one_requested() {
    let mut s = MissionServer::new(VEHICLE, MissionConfig::default());
    s.handle_message(
        T0,
        GCS,
        &MavMessage::MissionCount(MissionCount {
            target_system: 1,
            target_component: 1,
            count: 3,
            mission_type: MavMissionType::RALLY,
        }),
    );
    let _ = s.poll_transmit();
    let mut item = items(3);
    for (i, it) in item.iter_mut().enumerate() {
        it.seq = i as u16;
        it.target_system = 1;
        it.target_component = 1;
        it.mission_type = MavMissionType::RALLY;
    }
    s.handle_message(T0, GCS, &MavMessage::MissionItemInt(item[2]));
    assert!(matches!(
        s.poll_transmit().unwrap().message,
        MavMessage::MissionRequestInt(MissionRequestInt { seq: 0, .. })
    ));
    for it in &item {
        s.handle_message(T0, GCS, &MavMessage::MissionItemInt(*it));
    }
    let out: Vec<_> = core::iter::from_fn(|| s.poll_transmit())
        .map(|o| o.message)
        .collect();
    assert!(
        matches!(out.last(), Some(MavMessage::MissionAck(a)) if a.r#type == MavMissionResult::MAV_MISSION_ACCEPTED && a.mission_type == MavMissionType::RALLY)
    );
    assert_eq!(s.plan(MavMissionType::RALLY).len(), 3);
    // The last item again (its ACK was lost): ACKed again, not stored twice.
    s.handle_message(T0, GCS, &MavMessage::MissionItemInt(item[2]));
    assert!(matches!(
        s.poll_transmit().unwrap().message,
        MavMessage::MissionAck(_)
    ));
    // An unsupported plan type.
    s.handle_message(
        T0,
        GCS,
        &MavMessage::MissionCount(MissionCount {
            target_system: 1,
            target_component: 1,
            count: 3,
            mission_type: MavMissionType(7),
        }),
    );
    assert!(
        matches!(s.poll_transmit().unwrap().message, MavMessage::MissionAck(a) if a.r#type == MavMissionResult::MAV_MISSION_UNSUPPORTED)
    );
}

/// The client's next event is the mission uploaded and confirmed.
fn assert_uploaded(c: &mut MissionClient) {
    assert_eq!(
        c.poll_event(),
        Some(MissionEvent::Uploaded {
            mission_type: MavMissionType::MISSION,
            result: Ok(())
        })
    );
}

/// MISSION_REQUEST_INT for item `seq` of the mission, from the vehicle to us.
fn request_to_gcs(seq: u16) -> MavMessage {
    MavMessage::MissionRequestInt(MissionRequestInt {
        target_system: GCS.system,
        target_component: GCS.component,
        seq,
        mission_type: MavMissionType::MISSION,
    })
}

/// MISSION_ACK of the mission with `result`, from the vehicle to us.
fn ack_to_gcs(result: MavMissionResult) -> MavMessage {
    MavMessage::MissionAck(mavstack_dialects::common::MissionAck {
        target_system: GCS.system,
        target_component: GCS.component,
        r#type: result,
        mission_type: MavMissionType::MISSION,
    })
}

/// ArduPilot 4.7, its MISSION_REQUEST for item 1 lost: our resend of item 0 gets
/// MISSION_ACK INVALID_SEQUENCE, then it asks for item 1 again. The upload goes on.
#[test]
fn an_invalid_sequence_ack_mid_upload_does_not_end_it() {
    let mut c = MissionClient::new(GCS, MissionConfig::default());
    c.upload(T0, VEHICLE, MavMissionType::MISSION, items(2))
        .unwrap();
    let _count = c.poll_transmit();
    let (request, ack) = (request_to_gcs, ack_to_gcs);
    c.handle_message(T0, VEHICLE, &request(0));
    assert!(matches!(
        c.poll_transmit().unwrap().message,
        MavMessage::MissionItemInt(MissionItemInt { seq: 0, .. })
    ));
    // The request for 1 is lost; item 0 goes again on the timeout.
    let t = c.poll_timeout().unwrap();
    c.handle_timeout(t);
    assert!(c.poll_transmit().is_some());
    c.handle_message(
        t,
        VEHICLE,
        &ack(MavMissionResult::MAV_MISSION_INVALID_SEQUENCE),
    );
    assert_eq!(c.poll_event(), None, "not the end");
    // ArduPilot took item 0 (it asked for it and refuses the copy) and wants 1: item 1 goes
    // at once, without waiting a second for ArduPilot to ask again.
    assert!(matches!(
        c.poll_transmit().unwrap().message,
        MavMessage::MissionItemInt(MissionItemInt { seq: 1, .. })
    ));
    assert!(c.poll_transmit().is_none());
    // Its request for 1, sent meanwhile, is answered as a late copy.
    c.handle_message(t, VEHICLE, &request(1));
    assert!(matches!(
        c.poll_transmit().unwrap().message,
        MavMessage::MissionItemInt(MissionItemInt { seq: 1, .. })
    ));
    c.handle_message(t, VEHICLE, &ack(MavMissionResult::MAV_MISSION_ACCEPTED));
    assert_uploaded(&mut c);
}

/// The final ACK lost: the last item goes again, and ArduPilot, no longer in an upload,
/// answers MAV_MISSION_ERROR. That is not a refusal of the plan but an unknown outcome; the
/// same ERROR to the first send of the last item is a refusal.
#[test]
fn an_error_to_the_resent_last_item_is_unconfirmed() {
    let request = request_to_gcs(0);
    let error = ack_to_gcs(MavMissionResult::MAV_MISSION_ERROR);
    for resend in [true, false] {
        let mut c = MissionClient::new(GCS, MissionConfig::default());
        c.upload(T0, VEHICLE, MavMissionType::MISSION, items(1))
            .unwrap();
        let _count = c.poll_transmit();
        c.handle_message(T0, VEHICLE, &request);
        assert!(c.poll_transmit().is_some());
        let mut t = T0;
        if resend {
            t = c.poll_timeout().unwrap();
            c.handle_timeout(t);
            assert!(matches!(
                c.poll_transmit().unwrap().message,
                MavMessage::MissionItemInt(MissionItemInt { seq: 0, .. })
            ));
        }
        c.handle_message(t, VEHICLE, &error);
        let result = MavMissionResult::MAV_MISSION_ERROR;
        let want = if resend {
            MissionError::Unconfirmed { result }
        } else {
            MissionError::Rejected { result }
        };
        assert_eq!(
            c.poll_event(),
            Some(MissionEvent::Uploaded {
                mission_type: MavMissionType::MISSION,
                result: Err(want)
            })
        );
    }
}

/// An INVALID_SEQUENCE that does not answer a resend (a copy the link made of an earlier
/// item) moves nothing: the client waits for the vehicle's request.
#[test]
fn an_invalid_sequence_ack_without_a_resend_sends_nothing() {
    let mut c = MissionClient::new(GCS, MissionConfig::default());
    c.upload(T0, VEHICLE, MavMissionType::MISSION, items(3))
        .unwrap();
    let _count = c.poll_transmit();
    c.handle_message(T0, VEHICLE, &request_to_gcs(0));
    assert!(c.poll_transmit().is_some());
    let invalid = ack_to_gcs(MavMissionResult::MAV_MISSION_INVALID_SEQUENCE);
    c.handle_message(T0, VEHICLE, &invalid);
    assert!(c.poll_transmit().is_none());
    assert_eq!(c.poll_event(), None);
}

#[test]
fn sim_rejection_ends_the_upload() {
    let mut p = sim(Knobs::clean(), 6);
    p.a.upload(p.now, VEHICLE, MavMissionType(7), items(2))
        .unwrap();
    assert_eq!(
        wait(&mut p).0,
        MissionEvent::Uploaded {
            mission_type: MavMissionType(7),
            result: Err(MissionError::Rejected {
                result: MavMissionResult::MAV_MISSION_UNSUPPORTED
            })
        }
    );
}

#[test]
fn server_takes_float_mission_items_and_moves_current() {
    use mavstack_dialects::common::MissionItem;
    let mut s = MissionServer::new(VEHICLE, MissionConfig::default());
    s.handle_message(
        T0,
        GCS,
        &MavMessage::MissionCount(MissionCount {
            target_system: 1,
            target_component: 1,
            count: 2,
            ..Default::default()
        }),
    );
    for seq in 0..2u16 {
        let item = MissionItem {
            target_system: 1,
            target_component: 1,
            seq,
            frame: MavFrame::GLOBAL_RELATIVE_ALT,
            x: -35.363_26,
            y: 149.165_23,
            z: 20.0 + f32::from(seq),
            ..Default::default()
        };
        assert!(s.handle_message(T0, GCS, &MavMessage::MissionItem(item)));
    }
    let plan = s.plan(MavMissionType::MISSION);
    assert_eq!(plan.len(), 2);
    assert_eq!(plan[1].frame, MavFrame::GLOBAL_RELATIVE_ALT_INT);
    // degE7 of the f32 the item carried (f32 holds ~7 significant digits).
    assert!((plan[1].x + 353_632_600).abs() < 100, "{}", plan[1].x);
    assert!((plan[1].y - 1_491_652_300).abs() < 100, "{}", plan[1].y);
    assert_eq!(plan[1].z, 21.0);
    let sent: Vec<_> = core::iter::from_fn(|| s.poll_transmit()).collect();
    assert!(matches!(
        sent.last().map(|o| &o.message),
        Some(MavMessage::MissionAck(a)) if a.r#type == MavMissionResult::MAV_MISSION_ACCEPTED
    ));
    assert!(s.set_current(1));
    assert_eq!(s.current(), 1);
    assert!(!s.set_current(2));
    assert!(matches!(
        s.poll_transmit().map(|o| o.message),
        Some(MavMessage::MissionCurrent(c)) if c.seq == 1 && c.total == 2
    ));
}

/// The requests a client sent: their item numbers, in order.
fn requested(c: &mut MissionClient) -> Vec<u16> {
    core::iter::from_fn(|| c.poll_transmit())
        .filter_map(|o| match o.message {
            MavMessage::MissionRequestInt(r) => Some(r.seq),
            _ => None,
        })
        .collect()
}

/// Item `seq` of `plan`, as the vehicle sends it to us.
fn item_to_gcs(plan: &[MissionItemInt], seq: u16) -> MavMessage {
    MavMessage::MissionItemInt(MissionItemInt {
        seq,
        target_system: GCS.system,
        target_component: GCS.component,
        mission_type: MavMissionType::MISSION,
        ..plan[usize::from(seq)]
    })
}

/// With a window of 4 the client keeps the four items after the last it holds asked for:
/// an item that comes early is kept and asks again, once, for the items before it still
/// missing (the vehicle answers in order, so they were lost), the awaited one slides the
/// window, and a timeout asks again for exactly the items of the window still missing.
#[test]
fn a_windowed_download_asks_ahead_and_again_only_for_what_is_missing() {
    let plan = items(10);
    let config = MissionConfig {
        download_window: 4,
        ..MissionConfig::default()
    };
    let mut c = MissionClient::new(GCS, config);
    c.download(T0, VEHICLE, MavMissionType::MISSION).unwrap();
    let _ = c.poll_transmit();
    let count = MavMessage::MissionCount(MissionCount {
        target_system: GCS.system,
        target_component: GCS.component,
        count: 10,
        mission_type: MavMissionType::MISSION,
    });
    assert!(c.handle(T0, VEHICLE, &count));
    assert_eq!(requested(&mut c), [0, 1, 2, 3]);
    // Item 2 before 0: kept, the window stays, and 0 and 1 are asked for again.
    assert!(c.handle(T0, VEHICLE, &item_to_gcs(&plan, 2)));
    assert_eq!(requested(&mut c), [0, 1]);
    // A copy of it is not used again, and asks for nothing.
    assert!(!c.handle(T0, VEHICLE, &item_to_gcs(&plan, 2)));
    assert_eq!(requested(&mut c), [] as [u16; 0]);
    // Item 0: the window starts at 1, so 4 is asked for.
    assert!(c.handle(T0, VEHICLE, &item_to_gcs(&plan, 0)));
    assert_eq!(requested(&mut c), [4]);
    // Item 1: 0, 1 and 2 are in; the window is 3..7.
    assert!(c.handle(T0, VEHICLE, &item_to_gcs(&plan, 1)));
    assert_eq!(requested(&mut c), [5, 6]);
    // Item 8 is outside the window: not used.
    assert!(!c.handle(T0, VEHICLE, &item_to_gcs(&plan, 8)));
    // Item 5 passes the missing 3 and 4: asked for again.
    assert!(c.handle(T0, VEHICLE, &item_to_gcs(&plan, 5)));
    assert_eq!(requested(&mut c), [3, 4]);
    // Item 6 passes them too, but they were asked for again already.
    assert!(c.handle(T0, VEHICLE, &item_to_gcs(&plan, 6)));
    assert_eq!(requested(&mut c), [] as [u16; 0]);
    // Nothing more comes: the missing 3 and 4 are asked for again, not 5 or 6.
    let deadline = c.poll_timeout().unwrap();
    c.handle_timeout(deadline);
    let mut again = requested(&mut c);
    again.sort_unstable();
    assert_eq!(again, [3, 4]);
    for seq in [3, 4, 7, 8, 9] {
        assert!(c.handle(deadline, VEHICLE, &item_to_gcs(&plan, seq)));
    }
    let MissionEvent::Downloaded {
        result: Ok(got), ..
    } = c.poll_event().unwrap()
    else {
        panic!("not downloaded")
    };
    same_items(&got, &plan);
}

/// Windowed downloads through loss, duplication and reordering return the plan in order,
/// and on a clean slow link (100 ms each way) a window of 8 takes about an eighth of the
/// round trips one item at a time takes (virtual time, counted in round trips).
#[test]
fn sim_windowed_downloads_are_whole_and_take_fewer_round_trips() {
    let plan = items(200);
    let download = |knobs: Knobs, seed: u64, window: u16| {
        let config = MissionConfig {
            download_window: window,
            ..config(knobs)
        };
        let mut p = Pair::new(
            MissionClient::new(GCS, config),
            GCS,
            MissionServer::new(VEHICLE, config),
            VEHICLE,
            knobs,
            seed,
        );
        p.a.upload(p.now, VEHICLE, MavMissionType::MISSION, plan.clone())
            .unwrap();
        assert!(matches!(
            wait(&mut p).0,
            MissionEvent::Uploaded { result: Ok(()), .. }
        ));
        p.a.download(p.now, VEHICLE, MavMissionType::MISSION)
            .unwrap();
        let (e, took, _) = wait(&mut p);
        let MissionEvent::Downloaded {
            result: Ok(got), ..
        } = e
        else {
            panic!("window {window}, seed {seed}: {e:?}")
        };
        same_items(&got, &plan);
        took
    };
    for seed in 1..=6 {
        for window in [2, 8, 32] {
            download(Knobs::hostile(), seed, window);
        }
    }
    window_saves_round_trips("download", |knobs, window| download(knobs, 1, window));
}

/// A 200-item transfer (`transfer(knobs, window)`, its virtual time) on a clean slow link,
/// 100 ms each way: one round trip per item without a window, about an eighth of them with a
/// window of 8.
fn window_saves_round_trips(what: &str, transfer: impl Fn(Knobs, u16) -> Duration) {
    let slow = Knobs {
        latency: Duration::from_millis(100),
        ..Knobs::clean()
    };
    let round_trips = |t: Duration| t.as_millis() / 200;
    let one = round_trips(transfer(slow, 1));
    let eight = round_trips(transfer(slow, 8));
    eprintln!(
        "{what} of 200 items over 100 ms each way: {one} round trips one at a time, {eight} with a window of 8"
    );
    assert!(one >= 200, "{what} one at a time: {one} round trips");
    assert!(
        eight <= 200 / 8 + 3,
        "{what} with a window of 8: {eight} round trips"
    );
}

/// The items a client sent: their numbers, in order.
fn items_sent(c: &mut MissionClient) -> Vec<u16> {
    core::iter::from_fn(|| c.poll_transmit())
        .filter_map(|o| match o.message {
            MavMessage::MissionItemInt(i) => Some(i.seq),
            _ => None,
        })
        .collect()
}

/// With an upload window of 4 the client sends the four items from the one asked for; each
/// new request slides the window; a sign of loss (ArduPilot's INVALID_SEQUENCE, a repeated
/// request) sends the window again from the item asked for, once; a timeout does too.
#[test]
fn a_windowed_upload_sends_ahead_and_goes_back_once_per_loss() {
    let config = MissionConfig {
        upload_window: 4,
        ..MissionConfig::default()
    };
    let mut c = MissionClient::new(GCS, config);
    c.upload(T0, VEHICLE, MavMissionType::MISSION, items(10))
        .unwrap();
    let _ = c.poll_transmit();
    assert!(c.handle(T0, VEHICLE, &request_to_gcs(0)));
    assert_eq!(items_sent(&mut c), [0, 1, 2, 3]);
    assert!(c.handle(T0, VEHICLE, &request_to_gcs(1)));
    assert_eq!(items_sent(&mut c), [4]);
    // Request 2 lost; 3 came: items 5 and 6.
    assert!(c.handle(T0, VEHICLE, &request_to_gcs(3)));
    assert_eq!(items_sent(&mut c), [5, 6]);
    // A late copy of request 1: nothing.
    assert!(c.handle(T0, VEHICLE, &request_to_gcs(1)));
    assert_eq!(items_sent(&mut c), [] as [u16; 0]);
    // Item 3 was lost: ArduPilot refuses 4, 5 and 6. The window again from 3, once.
    let refused = ack_to_gcs(MavMissionResult::MAV_MISSION_INVALID_SEQUENCE);
    assert!(c.handle(T0, VEHICLE, &refused));
    assert_eq!(items_sent(&mut c), [3, 4, 5, 6]);
    assert!(c.handle(T0, VEHICLE, &refused));
    assert!(c.handle(T0, VEHICLE, &request_to_gcs(3)));
    assert_eq!(items_sent(&mut c), [] as [u16; 0]);
    // Nothing more comes: the timeout goes back to 3 again.
    let deadline = c.poll_timeout().unwrap();
    c.handle_timeout(deadline);
    assert_eq!(items_sent(&mut c), [3, 4, 5, 6]);
    // The rest flows; the request for the last item is answered and the ACK ends it.
    for seq in 4..10 {
        assert!(c.handle(deadline, VEHICLE, &request_to_gcs(seq)));
    }
    assert_eq!(items_sent(&mut c), [7, 8, 9]);
    assert!(c.handle(
        deadline,
        VEHICLE,
        &ack_to_gcs(MavMissionResult::MAV_MISSION_ACCEPTED)
    ));
    assert_uploaded(&mut c);
}

/// Windowed uploads through loss, duplication and reordering store the plan in place on a
/// server that refuses an item it did not expect as ArduPilot does and on one that asks
/// again at once, and end `Ok` or `Unconfirmed` (the final ACK lost: `System` reads the plan
/// back); on a clean slow link a window of 8 takes about an eighth of the round trips.
#[test]
fn sim_windowed_uploads_are_whole_and_take_fewer_round_trips() {
    use mavstack_services::mission::StrayItems;
    let plan = items(200);
    let upload = |knobs: Knobs, seed: u64, window: u16, stray: StrayItems| {
        let config = MissionConfig {
            upload_window: window,
            ..config(knobs)
        };
        let server = MissionConfig {
            stray_items: stray,
            ..config
        };
        let mut p = Pair::new(
            MissionClient::new(GCS, config),
            GCS,
            MissionServer::new(VEHICLE, server),
            VEHICLE,
            knobs,
            seed,
        );
        p.a.upload(p.now, VEHICLE, MavMissionType::MISSION, plan.clone())
            .unwrap();
        let (e, took, _) = wait(&mut p);
        match e {
            MissionEvent::Uploaded { result: Ok(()), .. }
            | MissionEvent::Uploaded {
                result: Err(MissionError::Unconfirmed { .. }),
                ..
            } => {}
            e => panic!("window {window}, seed {seed}, {stray:?}: {e:?}"),
        }
        same_items(p.b.plan(MavMissionType::MISSION), &plan);
        took
    };
    for seed in 1..=6 {
        for window in [2, 8, 32] {
            for stray in [StrayItems::ArduPilot, StrayItems::Reask] {
                upload(Knobs::hostile(), seed, window, stray);
            }
        }
    }
    window_saves_round_trips("upload", |knobs, window| {
        upload(knobs, 1, window, StrayItems::ArduPilot)
    });
}

/// A download from item `first` on asks only for the items from it to the vehicle's count,
/// returns them with their numbers, and returns none when the count does not reach it.
#[test]
fn a_download_from_an_item_on_asks_only_for_the_rest() {
    let plan = items(10);
    let count = |n| {
        MavMessage::MissionCount(MissionCount {
            target_system: GCS.system,
            target_component: GCS.component,
            count: n,
            mission_type: MavMissionType::MISSION,
        })
    };
    let mut c = MissionClient::new(GCS, MissionConfig::default());
    c.download_from(T0, VEHICLE, MavMissionType::MISSION, 8)
        .unwrap();
    let _ = c.poll_transmit();
    assert!(c.handle(T0, VEHICLE, &count(10)));
    assert_eq!(requested(&mut c), [8]);
    assert!(c.handle(T0, VEHICLE, &item_to_gcs(&plan, 8)));
    assert_eq!(requested(&mut c), [9]);
    assert!(c.handle(T0, VEHICLE, &item_to_gcs(&plan, 9)));
    let Some(MissionEvent::Downloaded {
        result: Ok(got), ..
    }) = c.poll_event()
    else {
        panic!("not downloaded")
    };
    assert_eq!(got.iter().map(|i| i.seq).collect::<Vec<_>>(), [8, 9]);

    c.download_from(T0, VEHICLE, MavMissionType::MISSION, 8)
        .unwrap();
    let _ = c.poll_transmit();
    assert!(c.handle(T0, VEHICLE, &count(8)));
    assert_eq!(requested(&mut c), [] as [u16; 0]);
    assert_eq!(
        c.poll_event(),
        Some(MissionEvent::Downloaded {
            mission_type: MavMissionType::MISSION,
            result: Ok(Vec::new())
        })
    );
}

/// After an upload whose final ACK was lost, a vehicle that stores mission items in place
/// (ArduPilot) is read back from the last item; fences, rally points and PX4 from item 0.
#[test]
fn the_read_back_of_an_unconfirmed_upload_starts_where_the_autopilot_allows() {
    use mavstack_dialects::common::MavAutopilot;
    let ardupilot = MissionConfig::default().for_autopilot(MavAutopilot::ARDUPILOTMEGA);
    let px4 = MissionConfig::default().for_autopilot(MavAutopilot::PX4);
    assert_eq!(ardupilot.readback_from(MavMissionType::MISSION, 30), 29);
    assert_eq!(ardupilot.readback_from(MavMissionType::MISSION, 0), 0);
    assert_eq!(ardupilot.readback_from(MavMissionType::FENCE, 30), 0);
    assert_eq!(ardupilot.readback_from(MavMissionType::RALLY, 30), 0);
    assert_eq!(px4.readback_from(MavMissionType::MISSION, 30), 0);
    assert_eq!(
        MissionConfig::default().readback_from(MavMissionType::MISSION, 30),
        0
    );
}

/// A vehicle busy with another transfer refuses to start the upload (PX4: MISSION_ACK ERROR
/// to the count while a download is open or another link transfers; ArduPilot: DENIED while
/// another ground station uploads): the count goes again after a pause, and the upload runs
/// once the vehicle asks for items. A refusal that lasts past `BUSY_WAIT`, or one that is not
/// about being busy (NO_SPACE), ends it.
#[test]
fn an_upload_the_vehicle_refuses_to_start_as_busy_is_asked_for_again() {
    use mavstack_services::mission::BUSY_WAIT;
    let count = |c: &mut MissionClient| {
        matches!(
            c.poll_transmit().map(|o| o.message),
            Some(MavMessage::MissionCount(MissionCount { count: 2, .. }))
        )
    };
    let rejected = |result| {
        Some(MissionEvent::Uploaded {
            mission_type: MavMissionType::MISSION,
            result: Err(MissionError::Rejected { result }),
        })
    };
    for busy in [
        MavMissionResult::MAV_MISSION_ERROR,
        MavMissionResult::MAV_MISSION_DENIED,
    ] {
        let mut c = MissionClient::new(GCS, MissionConfig::default());
        c.upload(T0, VEHICLE, MavMissionType::MISSION, items(2))
            .unwrap();
        assert!(count(&mut c));
        let refused = |c: &MissionClient| matches!(c.upload_state(), Some(Upload::AwaitingRequest(u)) if u.refused_as_busy());
        assert!(!refused(&c), "nothing refused yet");
        let mut t = T0;
        for _ in 0..3 {
            c.handle_message(t, VEHICLE, &ack_to_gcs(busy));
            assert_eq!(c.poll_event(), None, "not the end: {busy:?}");
            assert!(refused(&c), "told as busy (the caller warns the operator)");
            assert!(c.poll_transmit().is_none(), "nothing before the pause");
            t = c.poll_timeout().unwrap();
            assert!(t < T0 + BUSY_WAIT);
            c.handle_timeout(t);
            assert!(count(&mut c), "the count again");
        }
        c.handle_message(t, VEHICLE, &request_to_gcs(0));
        c.handle_message(t, VEHICLE, &request_to_gcs(1));
        let sent: Vec<u16> = core::iter::from_fn(|| c.poll_transmit())
            .filter_map(|o| match o.message {
                MavMessage::MissionItemInt(i) => Some(i.seq),
                _ => None,
            })
            .collect();
        assert!(sent.contains(&0) && sent.contains(&1), "{sent:?}");
        c.handle_message(
            t,
            VEHICLE,
            &ack_to_gcs(MavMissionResult::MAV_MISSION_ACCEPTED),
        );
        assert_uploaded(&mut c);

        // Busy for good: asked again until BUSY_WAIT has passed, then the refusal stands.
        let mut c = MissionClient::new(GCS, MissionConfig::default());
        c.upload(T0, VEHICLE, MavMissionType::MISSION, items(2))
            .unwrap();
        let mut t = T0;
        let mut counts = 0;
        while count(&mut c) {
            counts += 1;
            c.handle_message(t, VEHICLE, &ack_to_gcs(busy));
            if let Some(e) = c.poll_event() {
                assert_eq!(Some(e), rejected(busy));
                break;
            }
            t = c.poll_timeout().unwrap();
            c.handle_timeout(t);
        }
        assert!(t >= T0 + BUSY_WAIT && counts > 10, "{counts} counts");
    }
    // Not about being busy: at once.
    let mut c = MissionClient::new(GCS, MissionConfig::default());
    c.upload(T0, VEHICLE, MavMissionType::MISSION, items(2))
        .unwrap();
    assert!(count(&mut c));
    c.handle_message(
        T0,
        VEHICLE,
        &ack_to_gcs(MavMissionResult::MAV_MISSION_NO_SPACE),
    );
    assert_eq!(
        c.poll_event(),
        rejected(MavMissionResult::MAV_MISSION_NO_SPACE)
    );
}
