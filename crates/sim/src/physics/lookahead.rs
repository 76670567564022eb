//! Physics computed ahead: "the reads of this antenna window", served from windows computed
//! in parallel on the physics pool, with the caller's look-ahead hint (the windows it expects
//! to ask for next) computed in the background while it reports the current one, so that
//! `--speed max` keeps every core busy with the channel model. The reader only says what it
//! needs and what comes next ([`Lookahead::reads`]); when and where it is computed is decided
//! here.
//!
//! Sound because the physics is a pure function of (antenna, time window, transmit power,
//! channel) and a window split in two gives the same reads as the whole
//! ([`Model::inventory_with`]): the reads of any window inside a prefetched one are the
//! prefetched reads whose time falls in it. A request no prefetched window covers (another
//! power, a pinned channel, a slice the plan did not foresee) is computed directly, so the
//! prefetch changes only when the work is done, never what is read.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{mpsc, Arc};

use super::gen2::Air;
use super::pool::Pool;
use super::{Model, Read, Want};

/// One antenna's share of simulated time, as the running AISpec will ask for it.
#[derive(Clone, Debug, PartialEq)]
pub struct Slice {
    /// Antenna port, 1-based.
    pub antenna: u16,
    /// Transmit power the AISpec uses on it (`None`: the scenario's).
    pub power_dbm: Option<f64>,
    /// Start of the window, simulated µs.
    pub t0_us: u64,
    /// End of the window (exclusive), simulated µs.
    pub t1_us: u64,
    /// The optional values of the reads the AISpec reports.
    pub want: Want,
    /// RF mode, session and target the AISpec inventories with on this antenna.
    pub air: Air,
}

impl Slice {
    /// The reads of this slice, computed on the spot.
    pub fn compute(&self, model: &Model) -> Vec<Read> {
        model.inventory_with(
            self.antenna,
            self.t0_us,
            self.t1_us,
            self.power_dbm,
            None,
            self.want,
            &self.air,
        )
    }
}

#[derive(Debug)]
struct Window {
    slice: Slice,
    reads: Vec<Read>,
}

/// Most slices one prefetch computes.
pub const MAX_BATCH: usize = 256;

/// Batches computed in the background at once: while the reader reports one, the workers
/// work on the next ones, so they never wait for it to ask.
pub const AHEAD_DEPTH: usize = 2;

/// Prefetched windows in time order, and how many slices the next miss should plan.
#[derive(Debug)]
pub struct Lookahead {
    windows: VecDeque<Window>,
    /// Slices to plan at the next miss (0: not yet adapted, start at 8).
    batch: usize,
    /// Slices the last plan had.
    planned: usize,
    /// The following batches, being computed in the background, oldest first.
    ahead: VecDeque<Ahead>,
    /// The process's physics threads, shared with every other reader.
    pool: Arc<Pool>,
    /// End of the last slice planned (computed or being computed): the hint's slices before
    /// it are already on their way.
    planned_until_us: u64,
}

impl Default for Lookahead {
    fn default() -> Self {
        Lookahead::new(Pool::shared())
    }
}

/// The slices of a plan in lanes, one per worker, each antenna always in the same lane (so
/// its physics caches stay on one core), with a cursor each: a worker takes from its own
/// lane, then from the others' once it is empty, so all finish together.
#[derive(Debug)]
struct Queue {
    lanes: Vec<Vec<usize>>,
    cursors: Vec<AtomicUsize>,
}

impl Queue {
    /// Makes every slice not yet taken untakeable (a worker on this queue stops at its next
    /// slice).
    fn cancel(&self) {
        for (list, cursor) in self.lanes.iter().zip(&self.cursors) {
            cursor.fetch_max(list.len(), Ordering::Relaxed);
        }
    }

    /// The slices of `plan` in `lanes` lanes, in plan (time) order within each.
    fn new(plan: &[Slice], lanes: usize) -> Queue {
        let lanes = lanes.max(1);
        let mut lists = vec![Vec::new(); lanes];
        for (i, s) in plan.iter().enumerate() {
            lists[usize::from(s.antenna.saturating_sub(1)) % lanes].push(i);
        }
        Queue {
            cursors: lists.iter().map(|_| AtomicUsize::new(0)).collect(),
            lanes: lists,
        }
    }

    /// The next slice nobody has taken: from lane `own` first (none: any), then from the
    /// others; `None` once every slice is taken.
    fn take(&self, own: Option<usize>) -> Option<usize> {
        let first = own.into_iter();
        let rest = (0..self.lanes.len()).filter(|&l| Some(l) != own);
        for l in first.chain(rest) {
            if let (Some(list), Some(cursor)) = (self.lanes.get(l), self.cursors.get(l)) {
                if cursor.load(Ordering::Relaxed) < list.len() {
                    if let Some(&i) = list.get(cursor.fetch_add(1, Ordering::Relaxed)) {
                        return Some(i);
                    }
                }
            }
        }
        None
    }
}

fn same_power(a: Option<f64>, b: Option<f64>) -> bool {
    a.map(f64::to_bits) == b.map(f64::to_bits)
}

impl Lookahead {
    /// An empty prefetch computing on `pool`.
    pub fn new(pool: Arc<Pool>) -> Self {
        Lookahead {
            windows: VecDeque::new(),
            batch: 0,
            planned: 0,
            ahead: VecDeque::new(),
            pool,
            planned_until_us: 0,
        }
    }

    /// The reads of `slice` (the window the caller needs now). `dwell` is that window as its
    /// antenna will run it to the end (the same start, a later or equal end) and `upcoming`
    /// the look-ahead hint: the windows the caller expects to ask for after it, in order
    /// (it may end early, e.g. where an AISpec ends). A window computed ahead serves it;
    /// on a miss the oldest batch computed in the background is finished if it covers it,
    /// else `dwell` and the next slices of the hint are computed on every core; either way
    /// [`AHEAD_DEPTH`] batches of the hint after them go on computing in the background.
    pub fn reads(
        &mut self,
        model: &Arc<Model>,
        slice: &Slice,
        dwell: Slice,
        upcoming: impl IntoIterator<Item = Slice>,
    ) -> Vec<Read> {
        if let Some(reads) = self.take(slice) {
            return reads;
        }
        let batch = self.batch_after_miss(slice.t0_us);
        let mut upcoming = upcoming.into_iter();
        let hit = if self.finish_ahead() {
            self.take(slice)
        } else {
            None
        };
        let reads = match hit {
            Some(reads) => reads,
            None => {
                let dwell_end = dwell.t1_us;
                let mut plan = vec![dwell];
                plan.extend(upcoming.by_ref().take(batch.saturating_sub(1)));
                self.planned_until_us = plan.last().map_or(dwell_end, |s| s.t1_us);
                self.fill(model, plan);
                self.take(slice).unwrap_or_else(|| slice.compute(model))
            }
        };
        // The batches after: computed while this one's reads are reported.
        let until = self.planned_until_us;
        let mut rest = upcoming.skip_while(|s| s.t0_us < until);
        while self.ahead_count() < AHEAD_DEPTH {
            let ahead: Vec<Slice> = rest.by_ref().take(batch).collect();
            let Some(last) = ahead.last() else {
                break;
            };
            self.planned_until_us = last.t1_us;
            self.start_ahead(model, ahead);
        }
        reads
    }

    /// How many slices to plan after a miss at `t_us`: doubled (up to [`MAX_BATCH`]) while
    /// the plans are used, quartered when most of the last one went unused (e.g. an AISpec
    /// that ends at its first tag and restarts), so prefetching never costs much more than it
    /// saves.
    fn batch_after_miss(&mut self, t_us: u64) -> usize {
        let unused = self
            .windows
            .iter()
            .filter(|w| w.slice.t0_us >= t_us)
            .count();
        let planned = self.planned.max(1);
        self.batch = match self.batch {
            0 => 8,
            b if 2 * unused > planned => (b / 4).max(1),
            b => (b * 2).min(MAX_BATCH),
        };
        self.batch
    }

    /// The reads of `slice` if a prefetched window covers it; windows wholly before it are
    /// dropped.
    pub fn take(&mut self, slice: &Slice) -> Option<Vec<Read>> {
        while self
            .windows
            .front()
            .is_some_and(|w| w.slice.t1_us <= slice.t0_us)
        {
            self.windows.pop_front();
        }
        let w = self.windows.iter().find(|w| {
            w.slice.antenna == slice.antenna
                && same_power(w.slice.power_dbm, slice.power_dbm)
                && w.slice.want.covers(slice.want)
                && w.slice.air == slice.air
                && w.slice.t0_us <= slice.t0_us
                && slice.t1_us <= w.slice.t1_us
        })?;
        let lo = w.reads.partition_point(|r| r.time_us < slice.t0_us);
        let hi = w.reads.partition_point(|r| r.time_us < slice.t1_us);
        Some(w.reads[lo..hi].to_vec())
    }

    /// Hands `plan` to `n` threads of the pool, lane k to thread k: the receiver of the
    /// reads of each slice they take.
    fn dispatch(
        &self,
        model: &Arc<Model>,
        plan: &Arc<Vec<Slice>>,
        queue: &Arc<Queue>,
        n: usize,
    ) -> mpsc::Receiver<SliceReads> {
        let (reply, replies) = mpsc::channel();
        for lane in 0..n {
            let (model, plan, queue, reply) = (
                Arc::clone(model),
                Arc::clone(plan),
                Arc::clone(queue),
                reply.clone(),
            );
            // Lane k always goes to thread k: its antennas stay on one core. A thread that is
            // busy (with another reader's work, or the caller's own) starts late and finds
            // its lane taken by the others: nobody waits for a task that has not started.
            let task = Box::new(move || {
                while let Some(i) = queue.take(Some(lane)) {
                    if let Some(s) = plan.get(i) {
                        // The batch's owner may have gone; nothing else waits for these reads.
                        let _ = reply.send((i, s.compute(&model)));
                    }
                }
            });
            // A pool without threads leaves the lane to the caller, who takes every slice.
            let _ = self.pool.run_on(lane, task);
        }
        replies
    }

    /// Computes the reads of every slice of `plan` (in parallel) and keeps them, replacing
    /// what was prefetched before (batches still computed in the background are dropped).
    fn fill(&mut self, model: &Arc<Model>, plan: Vec<Slice>) {
        self.cancel_ahead();
        self.planned = plan.len();
        let plan = Arc::new(plan);
        let helpers = if plan.len() < 2 {
            0
        } else {
            self.pool.threads().saturating_sub(1)
        };
        // The calling thread works the last lane, then whatever nobody has taken.
        let queue = Arc::new(Queue::new(&plan, helpers + 1));
        let replies = self.dispatch(model, &plan, &queue, helpers);
        self.windows = collect(model, plan, &queue, &replies, Some(helpers)).into();
    }

    /// Starts computing `plan` in the background (the slices after the ones already
    /// prefetched); [`Self::finish_ahead`] adds them once needed.
    fn start_ahead(&mut self, model: &Arc<Model>, plan: Vec<Slice>) {
        if plan.is_empty() {
            return;
        }
        let plan = Arc::new(plan);
        // As many lanes as threads other than the caller's: it is busy reporting meanwhile.
        let n = if plan.len() < 2 {
            1
        } else {
            self.pool.helpers()
        };
        let queue = Arc::new(Queue::new(&plan, n.max(1)));
        let replies = self.dispatch(model, &plan, &queue, n);
        self.ahead.push_back(Ahead {
            model: Arc::clone(model),
            plan,
            queue,
            replies,
        });
    }

    /// How many batches are being computed in the background.
    fn ahead_count(&self) -> usize {
        self.ahead.len()
    }

    /// Drops the batches being computed in the background: their workers skip the slices
    /// they have not started.
    pub fn cancel_ahead(&mut self) {
        for a in self.ahead.drain(..) {
            a.queue.cancel();
        }
    }

    /// Computes what is left of the oldest background batch, if any, on the calling thread
    /// alongside the workers, waits for the slices they took and keeps its windows; whether
    /// there was one.
    fn finish_ahead(&mut self) -> bool {
        let Some(Ahead {
            model,
            plan,
            queue,
            replies,
        }) = self.ahead.pop_front()
        else {
            return false;
        };
        self.planned = plan.len();
        // The calling thread has no lane: it takes what the workers have not.
        let windows = collect(&model, plan, &queue, &replies, None);
        self.windows.extend(windows);
        true
    }
}

/// The reads of one slice of a plan: (index in the plan, reads).
type SliceReads = (usize, Vec<Read>);

/// Slices being computed in the background.
#[derive(Debug)]
struct Ahead {
    model: Arc<Model>,
    plan: Arc<Vec<Slice>>,
    /// The slices nobody has taken yet.
    queue: Arc<Queue>,
    /// The reads of the slices the workers took.
    replies: mpsc::Receiver<SliceReads>,
}

/// How long the caller waits for a slice a worker took before computing it itself (only a
/// worker that died with it, a panic in the physics, is that late; the physics is a pure
/// function, so the result is the same either way).
const SLICE_WAIT: std::time::Duration = std::time::Duration::from_secs(2);

/// The windows of `plan`: the caller takes slices from `queue` (lane `lane` first, then any)
/// until none is left, then waits for the ones the workers took.
fn collect(
    model: &Model,
    plan: Arc<Vec<Slice>>,
    queue: &Queue,
    replies: &mpsc::Receiver<SliceReads>,
    lane: Option<usize>,
) -> Vec<Window> {
    let mut results: Vec<Option<Vec<Read>>> = vec![None; plan.len()];
    while let Some(i) = queue.take(lane) {
        if let (Some(s), Some(r)) = (plan.get(i), results.get_mut(i)) {
            *r = Some(s.compute(model));
        }
    }
    // Every slice is taken now: the missing ones are being computed by running workers.
    let mut missing = results.iter().filter(|r| r.is_none()).count();
    while missing > 0 {
        match replies.recv_timeout(SLICE_WAIT) {
            Ok((i, reads)) => {
                if let Some(r @ None) = results.get_mut(i) {
                    *r = Some(reads);
                    missing -= 1;
                }
            }
            Err(_) => break,
        }
    }
    let plan = Arc::unwrap_or_clone(plan);
    plan.into_iter()
        .zip(results)
        .map(|(slice, reads)| Window {
            reads: reads.unwrap_or_else(|| slice.compute(model)),
            slice,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;

    /// `count` consecutive 25 ms slices from `t0_us`, on antennas 1..=`antennas` in turn.
    fn rotation(count: u64, antennas: u64, t0_us: u64) -> Vec<Slice> {
        (0..count)
            .map(|k| Slice {
                antenna: (k % antennas) as u16 + 1,
                power_dbm: None,
                t0_us: t0_us + k * 25_000,
                t1_us: t0_us + (k + 1) * 25_000,
                want: Want::ALL,
                air: Air::default(),
            })
            .collect()
    }

    /// The channel model of scenario S2.
    fn s2() -> Arc<Model> {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../fixtures/scenarios/s2.json"
        );
        let s = Scenario::load(std::path::Path::new(path)).expect("S2 loads");
        Arc::new(Model::new(&s, 0))
    }

    #[test]
    fn every_slice_is_taken_once_own_lane_first() {
        let plan = rotation(50, 8, 0);
        let q = Queue::new(&plan, 3);
        // Lane 1 holds antennas 2, 5 and 8, in time order.
        let mine: Vec<usize> = std::iter::from_fn(|| q.take(Some(1)))
            .take(q.lanes[1].len())
            .collect();
        assert!(mine.windows(2).all(|w| w[0] < w[1]));
        assert!(mine.iter().all(|&i| [2, 5, 8].contains(&plan[i].antenna)));
        // Then three takers share the rest, each slice once.
        let mut taken: Vec<usize> = std::thread::scope(|s| {
            let q = &q;
            let hs: Vec<_> = [Some(0), Some(2), None]
                .into_iter()
                .map(|lane| {
                    s.spawn(move || std::iter::from_fn(|| q.take(lane)).collect::<Vec<_>>())
                })
                .collect();
            hs.into_iter()
                .flat_map(|h| h.join().expect("taker"))
                .collect()
        });
        taken.extend(mine);
        taken.sort_unstable();
        assert_eq!(taken, (0..plan.len()).collect::<Vec<_>>());
        assert_eq!(q.take(None), None);
    }

    #[test]
    fn a_cancelled_queue_gives_nothing_more() {
        let plan = rotation(20, 4, 0);
        let q = Queue::new(&plan, 2);
        assert!(q.take(Some(0)).is_some());
        q.cancel();
        assert_eq!(q.take(Some(0)), None);
        assert_eq!(q.take(Some(1)), None);
        assert_eq!(q.take(None), None);
    }

    #[test]
    fn background_batches_finish_in_order_and_cancel() {
        let m = s2();
        let slices = rotation(48, 8, 60_000_000);
        let mut p = Lookahead::default();
        p.start_ahead(&m, slices[..16].to_vec());
        p.start_ahead(&m, slices[16..32].to_vec());
        assert_eq!(p.ahead_count(), 2);
        // The oldest first: after it, the first half is covered and the second is not yet.
        assert!(p.finish_ahead());
        assert!(p.take(&slices[15]).is_some());
        assert!(p.take(&slices[16]).is_none());
        assert!(p.finish_ahead());
        assert!(!p.finish_ahead(), "both taken");
        let mut total = 0;
        for s in &slices[16..32] {
            let got = p.take(s).expect("covered by the second batch");
            assert_eq!(got, s.compute(&m));
            total += got.len();
        }
        assert!(total > 0, "the robot passes the banners then");
        // A batch dropped before it is finished leaves nothing behind, and a fill replaces it.
        p.start_ahead(&m, slices[32..].to_vec());
        p.cancel_ahead();
        assert_eq!(p.ahead_count(), 0);
        assert!(!p.finish_ahead());
        assert!(p.take(&slices[40]).is_none());
        p.start_ahead(&m, slices[32..40].to_vec());
        p.fill(&m, slices[40..].to_vec());
        assert_eq!(
            p.ahead_count(),
            0,
            "a fill drops what was in the background"
        );
        for s in &slices[40..] {
            assert_eq!(p.take(s).expect("filled"), s.compute(&m));
        }
    }

    #[test]
    fn sub_windows_of_a_prefetch_equal_direct_computation() {
        let m = s2();
        let slices = rotation(64, 8, 60_000_000);
        // The first half computed at once, the second in the background.
        let mut p = Lookahead::default();
        p.fill(&m, slices[..32].to_vec());
        p.start_ahead(&m, slices[32..].to_vec());
        assert!(p.finish_ahead(), "a background plan was running");
        assert!(!p.finish_ahead(), "and it is taken once");
        let plan = slices;
        let mut total = 0;
        for s in &plan {
            // Each slice asked for in two pieces, as a step cut short by `to` would.
            let mid = s.t0_us + 10_001;
            for (t0, t1) in [(s.t0_us, mid), (mid, s.t1_us)] {
                let piece = Slice {
                    t0_us: t0,
                    t1_us: t1,
                    ..s.clone()
                };
                let got = p.take(&piece).expect("covered by the prefetch");
                let direct = m.inventory_on(s.antenna, t0, t1, None, None);
                assert_eq!(got, direct);
                total += got.len();
            }
        }
        assert!(
            total > 100,
            "the robot passes the banners then: {total} reads"
        );
        let other_power = Slice {
            power_dbm: Some(20.0),
            ..plan[31].clone()
        };
        assert!(
            p.take(&other_power).is_none(),
            "another power is not covered"
        );
    }
}
