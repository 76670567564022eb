//! The process's physics threads: one per core, shared by every simulated reader, so that N
//! readers never mean N pools. Work is a closure sent to one thread (by lane, so a reader's
//! antenna stays on one core and its caches with it) or to the next in turn. Work running on
//! a pool thread hands its lanes to the other threads ([`Pool::helpers`]), never to itself.
//! A second pool of the same size ([`Pool::readers`]) runs the readers' own work.

use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{mpsc, Arc, OnceLock};

/// Work for a physics thread.
pub type Task = Box<dyn FnOnce() + Send>;

thread_local! {
    /// On a pool's thread: the pool's ID and the thread's index in it.
    static CURRENT: Cell<Option<(usize, usize)>> = const { Cell::new(None) };
}

/// IDs for pools, so that a thread knows which pool it belongs to.
static NEXT_ID: AtomicUsize = AtomicUsize::new(0);

/// Threads that run physics work, parked while there is none.
#[derive(Debug)]
pub struct Pool {
    id: usize,
    /// One inbox per thread; a thread ends once its sender is dropped.
    inboxes: Vec<mpsc::Sender<Task>>,
    /// The thread the next [`Pool::run`] goes to.
    next: AtomicUsize,
}

impl Pool {
    /// A pool of `threads` threads named `llrp-physics` (fewer if the OS refuses some; none
    /// means callers compute everything themselves).
    pub fn new(threads: usize) -> Pool {
        let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
        let mut inboxes = Vec::with_capacity(threads);
        for index in 0..threads {
            let (tx, rx) = mpsc::channel::<Task>();
            let started = std::thread::Builder::new()
                .name("llrp-physics".into())
                .spawn(move || {
                    CURRENT.with(|c| c.set(Some((id, index))));
                    while let Ok(task) = rx.recv() {
                        task();
                    }
                });
            if started.is_err() {
                break; // indices stay contiguous
            }
            inboxes.push(tx);
        }
        Pool {
            id,
            inboxes,
            next: AtomicUsize::new(0),
        }
    }

    /// The physics pool of this process: one thread per core, at most 8, started on first
    /// use. Every reader's look-ahead physics runs here.
    pub fn shared() -> Arc<Pool> {
        static SHARED: OnceLock<Arc<Pool>> = OnceLock::new();
        SHARED.get_or_init(|| Arc::new(Pool::per_core())).clone()
    }

    /// The readers' pool of this process: one thread per core, at most 8, started on first
    /// use. A reader's own work while it inventories (running its ROSpec, building reports)
    /// runs here, so that it never waits behind look-ahead physics and never runs on an async
    /// worker thread.
    pub fn readers() -> Arc<Pool> {
        static READERS: OnceLock<Arc<Pool>> = OnceLock::new();
        READERS.get_or_init(|| Arc::new(Pool::per_core())).clone()
    }

    fn per_core() -> Pool {
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        Pool::new(cores.clamp(1, 8))
    }

    /// How many threads the pool has.
    pub fn threads(&self) -> usize {
        self.inboxes.len()
    }

    /// The index of the calling thread in this pool, if it is one of its threads.
    fn current(&self) -> Option<usize> {
        CURRENT
            .with(Cell::get)
            .and_then(|(id, index)| (id == self.id).then_some(index))
    }

    /// How many threads other than the calling one can take work (all of them when the caller
    /// is not one of the pool's).
    pub fn helpers(&self) -> usize {
        self.threads() - usize::from(self.current().is_some())
    }

    /// Runs `task` on helper `lane` (modulo [`Pool::helpers`]): always the same thread for the
    /// same lane and caller, never the calling thread. Gives it back if there is no helper
    /// (the caller then does the work).
    pub fn run_on(&self, lane: usize, task: Task) -> Result<(), Task> {
        let n = self.threads();
        let helpers = self.helpers();
        if helpers == 0 {
            return Err(task);
        }
        let k = lane % helpers;
        let thread = match self.current() {
            Some(me) => (me + 1 + k) % n,
            None => k,
        };
        self.inboxes[thread].send(task).map_err(|e| e.0)
    }

    /// Runs `task` on the next thread in turn; gives it back if the pool has no thread.
    pub fn run(&self, task: Task) -> Result<(), Task> {
        let n = self.threads();
        if n == 0 {
            return Err(task);
        }
        let thread = self.next.fetch_add(1, Ordering::Relaxed) % n;
        self.inboxes[thread].send(task).map_err(|e| e.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lanes_keep_their_thread_and_never_land_on_the_caller() {
        let pool = Arc::new(Pool::new(3));
        assert_eq!((pool.threads(), pool.helpers()), (3, 3));
        let (tx, rx) = mpsc::channel();
        for lane in [0, 1, 2, 3] {
            let tx = tx.clone();
            let sent = pool.run_on(
                lane,
                Box::new(move || {
                    let _ = tx.send((lane, std::thread::current().id()));
                }),
            );
            assert!(sent.is_ok());
        }
        let mut seen: Vec<_> = rx.iter().take(4).collect();
        seen.sort_by_key(|(lane, _)| *lane);
        assert_eq!(seen[0].1, seen[3].1, "lanes 0 and 3 share a thread");
        assert_ne!(seen[0].1, seen[1].1);
        // From a pool thread: two helpers, neither of them the caller.
        let (tx, rx) = mpsc::channel();
        let inner = Arc::clone(&pool);
        let outer = pool.run(Box::new(move || {
            let me = std::thread::current().id();
            let helpers = inner.helpers();
            let (ltx, lrx) = mpsc::channel();
            for lane in 0..4 {
                let ltx = ltx.clone();
                let _ = inner.run_on(
                    lane,
                    Box::new(move || {
                        let _ = ltx.send(std::thread::current().id());
                    }),
                );
            }
            let others: Vec<_> = lrx.iter().take(4).collect();
            let _ = tx.send((helpers, others.iter().all(|t| *t != me)));
        }));
        assert!(outer.is_ok());
        assert_eq!(rx.recv().expect("the outer task reports"), (2, true));
        let empty = Pool::new(0);
        assert!(empty.run(Box::new(|| {})).is_err());
        assert!(empty.run_on(0, Box::new(|| {})).is_err());
    }
}
