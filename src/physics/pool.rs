//! The process's physics threads: one per core, shared by every simulated reader, so that N
//! readers never mean N pools. Work is a closure sent to one thread (by lane, so a reader's
//! antenna stays on one core and its caches with it) or to the next in turn.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{mpsc, Arc, OnceLock};

/// Work for a physics thread.
pub type Task = Box<dyn FnOnce() + Send>;

/// Threads that run physics work, parked while there is none.
#[derive(Debug)]
pub struct Pool {
    /// One inbox per thread; a thread ends once its sender is dropped.
    inboxes: Vec<mpsc::Sender<Task>>,
    /// The thread the next [`Pool::run`] goes to.
    next: AtomicUsize,
}

impl Pool {
    /// A pool of `threads` threads named `llrp-physics` (fewer if the OS refuses some; none
    /// means callers compute everything themselves).
    pub fn new(threads: usize) -> Pool {
        let mut inboxes = Vec::with_capacity(threads);
        for _ in 0..threads {
            let (tx, rx) = mpsc::channel::<Task>();
            let started = std::thread::Builder::new()
                .name("llrp-physics".into())
                .spawn(move || {
                    while let Ok(task) = rx.recv() {
                        task();
                    }
                });
            if started.is_ok() {
                inboxes.push(tx);
            }
        }
        Pool {
            inboxes,
            next: AtomicUsize::new(0),
        }
    }

    /// The pool of this process: one thread per core, at most 8, started on first use.
    pub fn shared() -> Arc<Pool> {
        static SHARED: OnceLock<Arc<Pool>> = OnceLock::new();
        SHARED
            .get_or_init(|| {
                let cores = std::thread::available_parallelism().map_or(1, usize::from);
                Arc::new(Pool::new(cores.clamp(1, 8)))
            })
            .clone()
    }

    /// How many threads the pool has.
    pub fn threads(&self) -> usize {
        self.inboxes.len()
    }

    /// Runs `task` on thread `lane` (modulo the thread count); `false` if the pool has no
    /// thread to run it (the caller then does the work).
    pub fn run_on(&self, lane: usize, task: Task) -> bool {
        let n = self.inboxes.len();
        if n == 0 {
            return false;
        }
        self.inboxes[lane % n].send(task).is_ok()
    }

    /// Runs `task` on the next thread in turn; `false` if the pool has no thread.
    pub fn run(&self, task: Task) -> bool {
        let lane = self.next.fetch_add(1, Ordering::Relaxed);
        self.run_on(lane, task)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tasks_run_on_their_lane_and_a_pool_without_threads_says_so() {
        let pool = Pool::new(2);
        assert_eq!(pool.threads(), 2);
        let (tx, rx) = mpsc::channel();
        for lane in [0, 1, 2, 3] {
            let tx = tx.clone();
            assert!(pool.run_on(
                lane,
                Box::new(move || {
                    let _ = tx.send((lane, std::thread::current().id()));
                })
            ));
        }
        let mut seen: Vec<_> = rx.iter().take(4).collect();
        seen.sort_by_key(|(lane, _)| *lane);
        // Lanes 0 and 2 share a thread, 1 and 3 the other.
        assert_eq!(seen[0].1, seen[2].1);
        assert_eq!(seen[1].1, seen[3].1);
        assert_ne!(seen[0].1, seen[1].1);
        let empty = Pool::new(0);
        assert!(!empty.run(Box::new(|| {})));
    }
}
