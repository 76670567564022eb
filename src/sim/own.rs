//! The simulator's own inventory: while no LLRP client is connected (and simulated time runs
//! by the wall clock), each reader inventories every antenna by itself, as a reader set to
//! start inventory on its own would, and its reports go to the live localizer only, so a user
//! who only opens the map sees tags localize.
//!
//! It runs on a reader of its own, built afresh each time no client is connected: the reader
//! a client connects to never ran it, so the client sees exactly what it saw before (the
//! same ROSpecs, configuration and tag flags). The moment a client connects it stops.

use crate::reads::ReaderName;
use std::sync::Arc;

use bytes::Bytes;
use llrp::impinj::ImpinjEnableExtensions;
use llrp::message::{AddRospec, EnableRospec, StartRospec};
use llrp::{Inbound, Message};
use tokio::sync::{oneshot, watch};

use super::feed::Feed;
use crate::localize::live::{Input, Tap};
use crate::net::client::InventorySpec;
use crate::net::clock::Clock;
use crate::physics::pool::Pool;
use crate::reader::session::{Accepted, ClientId, Now, ServerSession, Session};
use crate::reader::Reader;
use llrp_gateway_vocab::feed::Inventory;

/// ROSpecID of the own inventory's ROSpec.
pub const ROSPEC_ID: u32 = 0x4F57_4E00;

/// Tags per RO_ACCESS_REPORT of the own inventory: a report per read (N counts distinct
/// tags, so a larger N would hold the reads of a scene with fewer tags until the end).
pub const REPORT_EVERY: u16 = 1;

/// A session driven by the simulator itself (sans IO).
pub struct OwnInventory {
    session: Session,
    client: ClientId,
}

impl OwnInventory {
    /// Connects to `reader` and starts an inventory of all its antennas with Impinj phase,
    /// peak RSSI and Doppler in the reports.
    pub fn start(reader: Reader, now: Now) -> Option<OwnInventory> {
        OwnInventory::start_with(reader, now, None, None)
    }

    /// [`OwnInventory::start`] with an RF mode (ModeIndex) and Gen2 session of the client's
    /// choosing; `None` keeps the reader's default.
    pub fn start_with(
        reader: Reader,
        now: Now,
        mode: Option<u16>,
        gen2_session: Option<u8>,
    ) -> Option<OwnInventory> {
        let mut session = Session::new(reader);
        let Accepted::Client(client) = session.connect(now) else {
            return None;
        };
        let spec = InventorySpec {
            rospec_id: ROSPEC_ID,
            impinj: true,
            report_every: REPORT_EVERY,
            keepalive_ms: 0,
            mode,
            session: gen2_session,
            ..InventorySpec::default()
        };
        let antennas = session.reader().model().antenna_count();
        let requests = [
            Message::new(1, ImpinjEnableExtensions::default()),
            Message::new(
                2,
                AddRospec {
                    ro_spec: spec.rospec(antennas),
                    ..Default::default()
                },
            ),
            Message::new(
                3,
                EnableRospec {
                    ro_spec_id: ROSPEC_ID,
                    ..Default::default()
                },
            ),
            Message::new(
                4,
                StartRospec {
                    ro_spec_id: ROSPEC_ID,
                    ..Default::default()
                },
            ),
        ];
        for m in requests {
            session.receive(client, Inbound::Frame(m.to_bytes().freeze()), now);
        }
        Some(OwnInventory { session, client })
    }

    /// Runs the reader up to `now`.
    pub fn advance(&mut self, now: Now) {
        self.session.advance(now);
    }

    /// The reader.
    pub fn reader(&self) -> &Reader {
        self.session.reader()
    }

    /// When to run next (simulated time).
    pub fn deadline(&self) -> crate::reader::session::Deadline {
        self.session.deadline()
    }

    /// The bytes the reader sent since the last call (responses and reports).
    pub fn take_output(&mut self) -> Option<Bytes> {
        let t = self.session.transmit()?;
        if t.to != self.client {
            return None;
        }
        Some(t.bytes.split().freeze())
    }
}

/// Everything the own inventory of one reader needs.
pub struct OwnTask {
    /// Makes a fresh reader each time the own inventory starts.
    pub make_reader: Box<dyn Fn() -> Reader + Send>,
    /// The simulation's clock.
    pub clock: Arc<Clock>,
    /// The localizer's tap.
    pub tap: Tap,
    /// The reader's name.
    pub name: ReaderName,
    /// The reader's pose and truth feed.
    pub feed: Box<dyn FnMut(&Reader) + Send>,
}

/// Runs the own inventory whenever `client` is false, until `shutdown` turns true.
pub async fn run(
    mut task: OwnTask,
    mut client: watch::Receiver<bool>,
    mut shutdown: watch::Receiver<bool>,
) {
    let pool = Pool::readers();
    loop {
        // Wait for no client.
        while *client.borrow_and_update() {
            tokio::select! {
                c = client.changed() => if c.is_err() { return },
                _ = shutdown.changed() => return,
            }
        }
        if *shutdown.borrow() {
            return;
        }
        let Some(mut own) = start(&task) else {
            return;
        };
        loop {
            offer_output(&task, &mut own);
            let wake = task
                .clock
                .wake_at(own.deadline())
                .map(tokio::time::Instant::from_std);
            tokio::select! {
                biased;
                _ = shutdown.changed() => return,
                c = client.changed() => {
                    if c.is_err() {
                        return;
                    }
                    client_changed(&task, &client);
                    break;
                }
                _ = sleep_until(wake) => {
                    let Some(o) = step(&mut task, &pool, own).await else {
                        return;
                    };
                    own = o;
                }
            }
        }
    }
}

/// Starts a fresh reader's own inventory at the clock's time and says so.
fn start(task: &OwnTask) -> Option<OwnInventory> {
    let now = Now {
        sim_us: task.clock.now_us(),
        wall_ms: task.clock.wall_ms(),
    };
    let own = OwnInventory::start((task.make_reader)(), now)?;
    task.tap
        .links()
        .update(&task.name, |l| l.inventory = Inventory::Own);
    tracing::info!(reader = %task.name, "no client: the reader inventories by itself for the localizer");
    Some(own)
}

/// Offers what the reader sent since the last call to the localizer's tap.
fn offer_output(task: &OwnTask, own: &mut OwnInventory) {
    if let Some(bytes) = own.take_output() {
        task.tap.offer(Input::Frames {
            reader: task.name.clone(),
            bytes,
            now_utc_us: own.reader().utc_us(own.reader().now_us()),
        });
    }
}

/// Logs a client's arrival: the own inventory stops (and starts again if it has gone).
fn client_changed(task: &OwnTask, client: &watch::Receiver<bool>) {
    // A client that came and went while a step ran (a session shorter than
    // one step, on a busy machine) changed the reader and its status too:
    // the own inventory starts again, as after any client.
    if *client.borrow() {
        tracing::info!(reader = %task.name, "a client connected: the reader's own inventory stops");
    }
}

/// Advances `own` to the clock's time on `pool`, feeding the poses; `None` if it was lost.
async fn step(task: &mut OwnTask, pool: &Pool, mut own: OwnInventory) -> Option<OwnInventory> {
    let (back, done) = oneshot::channel();
    let clock = task.clock.clone();
    let mut feed = std::mem::replace(&mut task.feed, Box::new(|_| {}));
    let job = Box::new(move || {
        let now = Now {
            sim_us: clock.now_us(),
            wall_ms: clock.wall_ms(),
        };
        own.advance(now);
        feed(own.reader());
        let _ = back.send((own, feed));
    });
    if let Err(job) = pool.run(job) {
        job();
    }
    match done.await {
        Ok((o, f)) => {
            task.feed = f;
            Some(o)
        }
        Err(_) => {
            tracing::error!(reader = %task.name, "the own inventory was lost in its physics");
            None
        }
    }
}

async fn sleep_until(at: Option<tokio::time::Instant>) {
    match at {
        Some(t) => tokio::time::sleep_until(t).await,
        None => std::future::pending().await,
    }
}

/// The reader's pose feed as a function of the reader (for [`OwnTask::feed`] and the
/// connected client's observer).
pub fn feed_fn(mut feed: Feed) -> Box<dyn FnMut(&Reader) + Send> {
    Box::new(move |r: &Reader| feed.feed(r.model(), r.now_us()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{Model, World};
    use crate::reader::ReaderProfile;
    use crate::scenario::Scenario;

    #[test]
    fn the_own_inventory_reports_every_read_with_phase_and_channel() {
        let s = Scenario::default_s1();
        let model = Arc::new(Model::in_world(&World::new(&s), &s, 0));
        let profile = ReaderProfile::from_scenario(&s, 0, &model);
        let reader = Reader::new(profile, model, 0);
        let mut own = OwnInventory::start(reader, Now::default()).expect("connects");
        let mut bytes = own.take_output().expect("responses").to_vec();
        for k in 1..=500u64 {
            own.advance(Now {
                sim_us: k * 10_000,
                wall_ms: k * 10,
            });
            if let Some(b) = own.take_output() {
                bytes.extend_from_slice(&b);
            }
        }
        let mut decoder = crate::reads::ReadDecoder::new(None)
            .with_fallback_table(Some(llrp::units::HopTable::fcc()));
        let mut reads = Vec::new();
        let mut at = 0;
        while let Some(h) = llrp::FrameHeader::peek(&bytes[at..]) {
            let len = h.length as usize;
            decoder
                .frame(&bytes[at..at + len], 0, &mut reads)
                .expect("decodes");
            at += len;
        }
        assert_eq!(at, bytes.len(), "whole frames");
        // The robot passes the first tags within its first 5 s: reads with phase and channel.
        assert!(reads.len() > 10, "{} reads", reads.len());
        assert!(reads
            .iter()
            .all(|r| r.phase_rad.is_some() && r.channel_index.is_some()));
    }
}
