//! The live localizer fed by the simulator in process: with no client connected each reader
//! inventories by itself and the estimates converge; a client that connects stops that
//! inventory and finds the reader as it always did (no ROSpec of the simulator's own), and
//! what its ROSpec reads reaches the localizer.

mod common;

use std::time::{Duration, Instant};

use common::*;
use llrp::message::GetRospecs;
use llrp::MessageBody;
use llrp_gateway::localize::estimate::State;
use llrp_gateway::localize::live::{Live, Settings};
use llrp_gateway::localize::shared::Shared;
use llrp_gateway::net::clock::Speed;
use llrp_gateway::sim::{self, feed, LocalizeFeed, PoseSource, SimOptions};

/// Polls `pred` on the localizer's state every 50 ms until it holds or `limit` passes.
async fn until(shared: &Shared, limit: Duration, pred: impl Fn(&Shared) -> bool) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        if pred(shared) {
            return true;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    pred(shared)
}

/// The simulator at 4× real time feeding `live`, with the robot's own poses and reads that
/// carry them.
fn own_poses_at_4x(live: &Live) -> SimOptions {
    SimOptions {
        speed: Speed::Factor(4.0),
        localize: Some(LocalizeFeed {
            tap: live.tap.clone(),
            poses: PoseSource::Estimated,
            pose_interval_us: feed::POSE_INTERVAL_US,
            read_poses: true,
        }),
        ..Default::default()
    }
}

fn live_for(scenario: &llrp_gateway::scenario::Scenario) -> Live {
    Live::start(feed::settings(scenario, Settings::default())).expect("starts")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_no_client_the_reader_inventories_by_itself_and_s1_tags_converge() {
    own_inventory_converges(true).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn s1_tags_converge_on_pose_samples_alone_when_reads_carry_no_pose() {
    own_inventory_converges(false).await;
}

/// S1 inventoried by the simulator itself; `read_poses`: its reads carry their antenna's pose
/// (else the localizer interpolates the 10 Hz pose samples).
async fn own_inventory_converges(read_poses: bool) {
    // Clean reads: on S1's own `impinj-r420` reads no tag's σ reaches the 1 cm of
    // `converged` (its 95 % ellipses hold; docs/localize.md).
    let scenario = s1_ideal();
    let live = live_for(&scenario);
    let opts = SimOptions {
        // The robot's 22 m at 0.5 m/s pass in under 3 s.
        speed: Speed::Factor(16.0),
        localize: Some(LocalizeFeed {
            tap: live.tap.clone(),
            poses: PoseSource::Truth,
            pose_interval_us: feed::POSE_INTERVAL_US,
            read_poses,
        }),
        ..Default::default()
    };
    let sim = sim::start(&scenario, &opts).await.expect("starts");
    let shared = live.shared.clone();
    let done = until(&shared, Duration::from_secs(60), |s| {
        let tags = s.tags();
        tags.len() == 10
            && tags.iter().all(|t| t.estimate.state == State::Converged)
            // The whole pass: the robot stops after 44 s.
            && s.truth().is_some_and(|t| t.antennas[0].pose.position[0] >= 22.5)
    })
    .await;
    let tags = shared.tags();
    let truth = shared.truth().expect("a simulation has ground truth");
    let readers = shared.readers();
    sim.shutdown().await;
    live.stop();
    assert!(
        done,
        "not all converged: {:?}",
        tags.iter()
            .map(|t| (&t.estimate.epc, t.estimate.state, t.estimate.samples))
            .collect::<Vec<_>>()
    );
    assert_eq!(readers.len(), 1);
    assert_eq!(readers[0].inventory, "self");
    assert!(!readers[0].connected);
    assert!(readers[0].reads > 0 && readers[0].antennas[0].pose.is_some());
    let mut errors = Vec::new();
    for t in &tags {
        let p = t.estimate.estimate.expect("converged has a position");
        let real = truth
            .tags
            .iter()
            .find(|x| x.epc == t.estimate.epc)
            .expect("every estimated tag is in the truth")
            .position;
        errors.push((p[0] - real[0]).hypot(p[1] - real[1]));
    }
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    let max = errors.iter().cloned().fold(0.0, f64::max);
    // With true poses (the live estimate works on thinned series): the 5 mm goal.
    assert!(
        mean <= 0.005 && max < 0.015,
        "mean {mean} m, max {max} m: {errors:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_stops_the_own_inventory_and_sees_the_reader_as_before() {
    let scenario = s1();
    let live = live_for(&scenario);
    let opts = own_poses_at_4x(&live);
    let sim = sim::start(&scenario, &opts).await.expect("starts");
    let shared = live.shared.clone();
    assert!(
        until(&shared, Duration::from_secs(30), |s| s
            .readers()
            .first()
            .is_some_and(|r| r.reads > 0))
        .await,
        "the own inventory read nothing"
    );
    let mut c = connect(&sim).await;
    // No ROSpec of the simulator's own is there for the client.
    let m = c
        .request(GetRospecs::default(), T)
        .await
        .expect("GET_ROSPECS");
    let MessageBody::GetRospecsResponse(r) = &m.body else {
        panic!("not a GET_ROSPECS_RESPONSE: {m:?}")
    };
    assert!(
        r.ro_specs.is_empty(),
        "the client sees ROSpecs: {:?}",
        r.ro_specs
    );
    assert!(
        until(&shared, Duration::from_secs(10), |s| s.readers()[0]
            .connected
            && s.readers()[0].inventory == "idle")
        .await,
        "the localizer was not told of the client: {:?}",
        shared.readers()
    );
    // The own inventory has stopped: once what was on its way is in, the reads the localizer
    // takes in stay put (while it ran they grew by hundreds a second).
    let mut still = shared.readers()[0].reads;
    let mut settled = false;
    for _ in 0..30 {
        tokio::time::sleep(Duration::from_millis(300)).await;
        let now = shared.readers()[0].reads;
        if now == still {
            settled = true;
            break;
        }
        still = now;
    }
    assert!(settled, "the reads still grow: {still}");
    // The client's own ROSpec feeds the localizer.
    c.enable_impinj_extensions(T).await.expect("extensions");
    let spec = rospec(
        1,
        vec![0],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1),
    );
    c.add_rospec(spec, T).await.expect("ADD_ROSPEC");
    c.enable_rospec(1, T).await.expect("ENABLE_ROSPEC");
    let (tags, _) = collect_reports(&mut c, T, |t| t.len() >= 50).await;
    assert!(tags.len() >= 50);
    assert!(
        until(&shared, Duration::from_secs(10), |s| s.readers()[0].reads
            >= still + 50
            && s.readers()[0].inventory == "client")
        .await,
        "the client's reads did not reach the localizer: {:?}",
        shared.readers()
    );
    drop(c);
    sim.shutdown().await;
    live.stop();
}

/// How a client of [`clients_leaving_every_way_hand_the_reader_back_to_its_own_inventory`]
/// leaves.
#[derive(Clone, Copy, Debug)]
enum Leave {
    /// CLOSE_CONNECTION, its response, then the reader's close.
    CloseConnection,
    /// It stops answering keepalives; the reader closes after three misses.
    KeepaliveTimeout,
    /// A TCP close (FIN) with no LLRP goodbye.
    TcpClose,
    /// A TCP reset (SO_LINGER 0), as of a process killed with its socket.
    Reset,
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_leaving_every_way_hand_the_reader_back_to_its_own_inventory() {
    let scenario = s1();
    let live = live_for(&scenario);
    let opts = own_poses_at_4x(&live);
    let sim = sim::start(&scenario, &opts).await.expect("starts");
    let shared = live.shared.clone();
    // The reader's view (none until the localizer has taken in the reader).
    let reader = |s: &Shared| s.readers().into_iter().next();
    let own_reads = |shared: &Shared, more_than: u64| {
        reader(shared).is_some_and(|r| {
            !r.connected && r.peer.is_none() && r.inventory == "self" && r.reads > more_than
        })
    };
    assert!(
        until(&shared, Duration::from_secs(30), |s| own_reads(s, 0)
            && reader(s).is_some_and(|r| r.reads_per_s > 0.0)
            && s.tags().iter().any(|t| t.reads_per_s > 0.0))
        .await,
        "the own inventory read nothing: {:?}",
        shared.readers()
    );
    for (k, leave) in [
        Leave::CloseConnection,
        Leave::KeepaliveTimeout,
        Leave::TcpClose,
        Leave::Reset,
    ]
    .into_iter()
    .enumerate()
    {
        if let Leave::Reset = leave {
            let s = tokio::net::TcpStream::connect(sim.addrs[0])
                .await
                .expect("connects");
            assert!(
                until(&shared, Duration::from_secs(10), |s| s.readers()[0]
                    .connected)
                .await,
                "{leave:?}: the client is not shown: {:?}",
                shared.readers()
            );
            // Closing with a zero linger sends RST, not FIN (deprecated in tokio because the
            // drop of a socket with a nonzero linger may block; a zero one never does).
            #[allow(deprecated)]
            s.set_linger(Some(Duration::ZERO)).expect("SO_LINGER");
            drop(s);
            let before = shared.readers()[0].reads;
            assert!(
                until(&shared, Duration::from_secs(30), |s| own_reads(s, before)).await,
                "{leave:?}: the reader did not go back to its own inventory: {:?}",
                shared.readers()
            );
            continue;
        }
        let mut c = connect(&sim).await;
        assert!(
            until(&shared, Duration::from_secs(10), |s| reader(s)
                .is_some_and(|r| r.connected && r.peer.is_some()))
            .await,
            "{leave:?}: the client is not shown: {:?}",
            shared.readers()
        );
        if k == 0 {
            // The client has not asked for an inventory yet: no reads come, and the rates
            // say so instead of keeping their last value.
            assert!(
                until(&shared, Duration::from_secs(30), |s| s.readers()[0]
                    .reads_per_s
                    == 0.0
                    && s.tags().iter().all(|t| t.reads_per_s == 0.0))
                .await,
                "rates stay up with no reads: {:?} {:?}",
                shared.readers(),
                shared
                    .tags()
                    .iter()
                    .map(|t| t.reads_per_s)
                    .collect::<Vec<_>>()
            );
        }
        // The client inventories: its reads reach the localizer.
        let id = 10 + k as u32;
        let spec = rospec(
            id,
            vec![0],
            ro_null(),
            ai_null(),
            full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1),
        );
        c.add_rospec(spec, T).await.expect("ADD_ROSPEC");
        c.enable_rospec(id, T).await.expect("ENABLE_ROSPEC");
        let (tags, _) = collect_reports(&mut c, T, |t| !t.is_empty()).await;
        assert!(!tags.is_empty(), "{leave:?}: the client read nothing");
        assert!(
            until(&shared, Duration::from_secs(10), |s| s.readers()[0]
                .inventory
                == "client")
            .await,
            "{leave:?}: {:?}",
            shared.readers()
        );
        c.delete_rospec(0, T).await.expect("DELETE_ROSPEC 0");
        match leave {
            Leave::CloseConnection => c.close_connection(T).await.expect("a clean close"),
            Leave::KeepaliveTimeout => {
                let set = llrp::message::SetReaderConfig {
                    keepalive_spec: Some(llrp::params::KeepaliveSpec {
                        keepalive_trigger_type: KeepaliveTriggerType::Periodic,
                        periodic_trigger_value: 100,
                        ..Default::default()
                    }),
                    ..Default::default()
                };
                assert_eq!(request_status(&mut c, set).await, StatusCode::M_Success);
                // Keepalives are not acknowledged: the reader gives up and closes.
                c.until_closed(Duration::from_secs(20))
                    .await
                    .expect("the reader closes a silent client");
            }
            Leave::TcpClose => c.close(T).await.expect("closed"),
            Leave::Reset => unreachable!("handled above"),
        }
        let before = shared.readers()[0].reads;
        assert!(
            until(&shared, Duration::from_secs(30), |s| own_reads(s, before)).await,
            "{leave:?}: the reader did not go back to its own inventory: {:?}",
            shared.readers()
        );
    }
    sim.shutdown().await;
    live.stop();
}

/// Every time the API shows is on the reads' clock (UTC µs for an LLRP reader): a pose's
/// `t_us` in `/api/readers` and `/api/truth` and a tag's `last_seen` agree to seconds (a pose
/// used to show simulated time since the start, 1.8·10¹⁵ µs off).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn poses_reads_and_truth_share_the_reads_clock() {
    let scenario = s1();
    let live = live_for(&scenario);
    let opts = own_poses_at_4x(&live);
    let sim = sim::start(&scenario, &opts).await.expect("starts");
    let shared = live.shared.clone();
    let ready = |s: &Shared| {
        s.readers()
            .first()
            .is_some_and(|r| r.antennas.first().is_some_and(|a| a.pose.is_some()))
            && s.tags().iter().any(|t| t.last_seen_us > 0)
            && s.truth().is_some()
    };
    assert!(
        until(&shared, Duration::from_secs(30), ready).await,
        "no pose, read or truth"
    );
    let pose_t = shared.readers()[0].antennas[0]
        .pose
        .as_ref()
        .map(|p| p.t_us)
        .expect("a pose");
    let seen = shared
        .tags()
        .iter()
        .map(|t| t.last_seen_us)
        .max()
        .expect("a tag");
    let truth_t = shared.truth().expect("truth").antennas[0].t_us;
    sim.shutdown().await;
    live.stop();
    let apart = |a: u64, b: u64| a.abs_diff(b);
    // Seconds apart at most (the pose feed, the reads and the truth update at their own pace).
    assert!(
        apart(pose_t, seen) < 30_000_000,
        "pose {pose_t}, read {seen}"
    );
    assert!(
        apart(truth_t, seen) < 30_000_000,
        "truth {truth_t}, read {seen}"
    );
}
