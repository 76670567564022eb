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
    let scenario = s1();
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
            && s.truth().is_some_and(|t| t.antennas[0].x >= 22.5)
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
    let opts = SimOptions {
        speed: Speed::Factor(4.0),
        localize: Some(LocalizeFeed {
            tap: live.tap.clone(),
            poses: PoseSource::Estimated,
            pose_interval_us: feed::POSE_INTERVAL_US,
            read_poses: true,
        }),
        ..Default::default()
    };
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
