//! The simulation's ground truth: each reader's antenna poses (true, estimated, odometry)
//! and the tags' positions every [`TRUTH_INTERVAL_US`] of simulated time, as JSONL.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::watch;

use super::TRUTH_INTERVAL_US;
use crate::localize::poses::PoseSample;
use crate::net::clock::{Clock, Speed};
use crate::physics::{AntennaPose, Model};
use crate::reads::ReaderName;
use crate::record::mcap::geo::{RobotAt, Truth as McapTruth};
use crate::record::mcap::{McapItem, McapSender};

/// Ground-truth writer shared by the readers: to the truth file (`--truth`), to the MCAP
/// file (`--mcap`), or both.
pub(super) struct Truth {
    out: Option<Mutex<BufWriter<File>>>,
    mcap: Option<McapSender>,
    /// Instants the MCAP writer had no room for (dropped rather than stall the simulation).
    mcap_dropped: AtomicU64,
}

impl Truth {
    /// A writer to `out` and `mcap`.
    pub(super) fn new(out: Option<Mutex<BufWriter<File>>>, mcap: Option<McapSender>) -> Truth {
        Truth {
            out,
            mcap,
            mcap_dropped: AtomicU64::new(0),
        }
    }

    /// Appends one line (buffered; a full disk must not stop the reader, so errors are
    /// dropped).
    pub(super) fn line(&self, value: &serde_json::Value) {
        let Some(out) = &self.out else {
            return;
        };
        let mut out = out.lock().unwrap_or_else(|e| e.into_inner());
        if serde_json::to_writer(&mut *out, value).is_ok() {
            let _ = out.write_all(b"\n");
        }
    }

    /// Hands one instant to the MCAP writer if its queue has room (the writer runs on its
    /// own thread; a sender here may be an async worker, which must not wait).
    fn mcap(&self, t: McapTruth) {
        if let Some(m) = &self.mcap {
            if !m.try_send(McapItem::Truth(t))
                && self.mcap_dropped.fetch_add(1, Ordering::Relaxed) == 0
            {
                tracing::warn!(
                    "the MCAP writer is behind (or gone): poses and truth are dropped while it is"
                );
            }
        }
    }

    pub(super) fn flush(&self) {
        if let Some(out) = &self.out {
            let _ = out.lock().unwrap_or_else(|e| e.into_inner()).flush();
        }
    }
}

fn hex(epc: &[u8]) -> String {
    epc.iter().map(|b| format!("{b:02x}")).collect()
}

/// `pose` of antenna `antenna` of reader `reader` at `t_us` as a pose-file record (keys
/// `t_us, reader, antenna, x, y, z, yaw_deg, pitch_deg`).
fn pose_record(
    t_us: u64,
    reader: &ReaderName,
    antenna: u16,
    pose: &AntennaPose,
) -> serde_json::Value {
    serde_json::json!(PoseSample {
        t_us,
        reader: Some(reader.clone()),
        antenna,
        pose: *pose,
    })
}

/// `pose` as the truth file's `pose` and `odometry` keys have it, in SI units (keys
/// `position, yaw_rad, pitch_rad`).
fn si_pose(pose: &AntennaPose) -> serde_json::Value {
    serde_json::json!({
        "position": pose.position,
        "yaw_rad": pose.yaw_rad,
        "pitch_rad": pose.pitch_rad,
    })
}

/// Writes reader `name`'s antenna poses (true, estimated and odometry) and the tags'
/// positions every [`TRUTH_INTERVAL_US`] of simulated time, up to the time it is called with.
pub(super) fn truth_writer(
    truth: Arc<Truth>,
    name: ReaderName,
    moving: Vec<usize>,
    utc0: u64,
    m: Arc<Model>,
) -> impl FnMut(u64) + Send {
    let mut next = 0u64;
    // Each robot carrying one of the reader's antennas, with the ports it carries.
    let mut carriers: Vec<(usize, Vec<u16>)> = Vec::new();
    for a in 1..=m.antenna_count() {
        if let Some(robot) = m.antenna_robot(a) {
            match carriers.iter_mut().find(|(r, _)| *r == robot) {
                Some((_, ports)) => ports.push(a),
                None => carriers.push((robot, vec![a])),
            }
        }
    }
    move |now_us: u64| {
        while next <= now_us {
            let t = next;
            let poses: Vec<_> = (1..=m.antenna_count())
                .map(|a| (a, m.antenna_pose(a, t), m.estimated_pose(a, t)))
                .collect();
            let antennas: Vec<_> = poses
                .iter()
                .map(|(a, true_pose, estimated)| {
                    serde_json::json!({
                        "antenna": a,
                        "true": pose_record(t, &name, *a, true_pose),
                        "estimated": pose_record(t, &name, *a, estimated),
                        "pose": si_pose(true_pose),
                        "odometry": si_pose(&m.odometry_pose(*a, t)),
                    })
                })
                .collect();
            let tags: Vec<usize> = if t == 0 {
                (0..m.tag_count()).collect()
            } else {
                moving.clone()
            };
            let tags: Vec<_> = tags
                .into_iter()
                .map(|k| (hex(m.tag_epc(k).as_bytes()), m.tag_position(k, t)))
                .collect();
            let tag_lines: Vec<_> = tags
                .iter()
                .map(|(epc, p)| serde_json::json!({"epc": epc, "position": p}))
                .collect();
            let robots = (carriers.iter())
                .filter_map(|(robot, ports)| {
                    Some(RobotAt {
                        name: robot_frame(*robot),
                        true_pose: m.robot_pose(*robot, t)?,
                        reported: m.robot_reported_pose(*robot, t)?,
                        ports: ports.clone(),
                    })
                })
                .collect();
            truth.mcap(McapTruth {
                reader: name.to_string(),
                utc_us: utc0 + t,
                antennas: poses,
                tags,
                robots,
            });
            truth.line(&serde_json::json!({
                "reader": name,
                "t_us": t,
                "utc_us": utc0 + t,
                "antennas": antennas,
                "tags": tag_lines,
            }));
            next += TRUTH_INTERVAL_US;
        }
    }
}

/// The frame of robot `robot` (an index into the scenario's distinct robots): `robot_N`,
/// N from 1.
pub(super) fn robot_frame(robot: usize) -> String {
    format!("robot_{}", robot + 1)
}

/// Writes the truth by the clock (real-time speeds), whoever drives the inventory: a client,
/// the own inventory or nobody. Ends at `shutdown`, after writing up to that moment.
pub(super) async fn truth_by_clock(
    mut write: impl FnMut(u64) + Send,
    clock: Arc<Clock>,
    mut shutdown: watch::Receiver<bool>,
) {
    let Speed::Factor(f) = clock.speed() else {
        return;
    };
    // One line's worth of simulated time, but not more often than every 10 ms.
    let every =
        Duration::from_secs_f64(TRUTH_INTERVAL_US as f64 / 1e6 / f).max(Duration::from_millis(10));
    let mut tick = tokio::time::interval(every);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        write(clock.now_us());
        tokio::select! {
            _ = tick.tick() => {}
            _ = shutdown.changed() => {
                write(clock.now_us());
                return;
            }
        }
    }
}
