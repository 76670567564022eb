//! What every LLRP server here shares (the simulated reader's, the replay's, the proxy's): the
//! shutdown check, the pause after a failed accept, the wait for an optional deadline, a
//! refusal written within a bound, and one accept loop with a connection limit and tracked
//! connection tasks (after mini-redis' `Listener`), which the proxy runs: each of its
//! connections is a task of its own.
//!
//! A server whose one sans-IO session owns every connection (the simulated reader, the
//! replay) is served by [`drive`](super::drive) instead, which uses the same pieces.

use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncWrite, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{watch, Semaphore};
use tokio::task::JoinSet;

use super::backoff::Backoff;

/// Least pause after a failed accept (out of file descriptors, a connection reset before it
/// was taken)...
pub const ACCEPT_BACKOFF_MIN: Duration = Duration::from_millis(10);
/// ... about doubled after each further failure, up to this ([`accept_backoff`]).
pub const ACCEPT_BACKOFF_MAX: Duration = Duration::from_secs(1);

/// How long the accept loop waits, once stopped, for its connections' tasks to end (each
/// closes on the shutdown signal by itself) before it aborts those left.
pub const DRAIN: Duration = Duration::from_secs(5);

/// Whether the shutdown signal `shutdown`, whose `changed()` gave `changed`, asks to stop:
/// it turned true, or its sender is gone (it can never ask again, so that is taken as the
/// stop rather than polled again and again).
pub fn stopping(
    changed: Result<(), watch::error::RecvError>,
    shutdown: &watch::Receiver<bool>,
) -> bool {
    changed.is_err() || *shutdown.borrow()
}

/// The pause after failed accepts: the shared [`Backoff`] (with jitter) from
/// [`ACCEPT_BACKOFF_MIN`] up to [`ACCEPT_BACKOFF_MAX`], reset after an accept succeeds.
pub fn accept_backoff() -> Backoff {
    Backoff::new(ACCEPT_BACKOFF_MIN, ACCEPT_BACKOFF_MAX, None)
}

/// Waits until `at`; forever when there is no deadline.
pub async fn sleep_until(at: Option<tokio::time::Instant>) {
    match at {
        Some(t) => tokio::time::sleep_until(t).await,
        None => std::future::pending().await,
    }
}

/// Writes `bytes` (a refusal: what a reader tells a client it does not take) and closes,
/// within `within`; a peer that does not read in time is closed all the same.
pub async fn refuse<S: AsyncWrite + Unpin>(mut stream: S, bytes: &[u8], within: Duration) {
    let _ = tokio::time::timeout(within, async {
        stream.write_all(bytes).await?;
        stream.flush().await?;
        stream.shutdown().await
    })
    .await;
}

/// Accepts on `listener` until `shutdown` asks to stop. Each connection, while fewer than
/// `limit` are served, goes to `serve` in a task of its own; one over the limit goes to
/// `over` (a refusal, in a task too, at most `limit` of them at once; beyond that it is closed
/// at once). Once stopped, waits up to [`DRAIN`] for the tasks to end and aborts the rest.
/// `what` names the server in logs.
pub async fn accept_loop<F, Fut, O, OFut>(
    listener: &TcpListener,
    limit: usize,
    mut shutdown: watch::Receiver<bool>,
    what: &str,
    mut serve: F,
    over: O,
) -> io::Result<()>
where
    F: FnMut(TcpStream, SocketAddr) -> Fut,
    Fut: Future<Output = ()> + Send + 'static,
    O: Fn(TcpStream, SocketAddr) -> OFut,
    OFut: Future<Output = ()> + Send + 'static,
{
    let limit = limit.max(1);
    let slots = Arc::new(Semaphore::new(limit));
    let refusals = Arc::new(Semaphore::new(limit));
    let mut tasks = JoinSet::new();
    let mut backoff = accept_backoff();
    loop {
        tokio::select! {
            changed = shutdown.changed() => {
                if stopping(changed, &shutdown) {
                    break;
                }
            }
            Some(_) = tasks.join_next(), if !tasks.is_empty() => {}
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    backoff.reset();
                    if let Ok(slot) = Arc::clone(&slots).try_acquire_owned() {
                        let task = serve(stream, peer);
                        tasks.spawn(async move {
                            task.await;
                            drop(slot);
                        });
                    } else if let Ok(slot) = Arc::clone(&refusals).try_acquire_owned() {
                        tracing::info!(%peer, limit, "{what}: connection refused: {limit} served already");
                        let task = over(stream, peer);
                        tasks.spawn(async move {
                            task.await;
                            drop(slot);
                        });
                    } else {
                        tracing::warn!(%peer, limit, "{what}: connection closed: {limit} served and {limit} being refused");
                    }
                }
                Err(e) => {
                    let pause = backoff.failed();
                    tracing::warn!("{what}: accept failed: {e}; pausing accepts for {pause:?}");
                    tokio::time::sleep(pause).await;
                }
            },
        }
    }
    let drained =
        tokio::time::timeout(DRAIN, async { while tasks.join_next().await.is_some() {} }).await;
    if drained.is_err() {
        tracing::warn!(
            "{what}: {} connections still open {DRAIN:?} after the stop: aborted",
            tasks.len()
        );
        tasks.shutdown().await;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_accept_backoff_grows_to_its_cap_and_starts_over_after_a_success() {
        let mut b = accept_backoff().seeded(5);
        let pauses: Vec<Duration> = (0..9).map(|_| b.failed()).collect();
        assert!(pauses[0] >= ACCEPT_BACKOFF_MIN && pauses[0] <= 2 * ACCEPT_BACKOFF_MIN);
        assert!(pauses[..6].windows(2).all(|w| w[1] >= w[0]), "{pauses:?}");
        let last = *pauses.last().expect("nine");
        assert!(last >= ACCEPT_BACKOFF_MAX / 2 && last <= ACCEPT_BACKOFF_MAX);
        b.reset();
        assert!(b.failed() <= 2 * ACCEPT_BACKOFF_MIN);
    }

    #[tokio::test]
    async fn over_the_limit_a_connection_is_refused_while_the_served_ones_hold_their_slots() {
        let listener = TcpListener::bind("127.0.0.1:0").await.expect("binds");
        let addr = listener.local_addr().expect("bound");
        let (stop, shutdown) = watch::channel(false);
        // Each served connection is held until its peer closes; a refused one is told "no".
        let server = tokio::spawn(async move {
            accept_loop(
                &listener,
                2,
                shutdown,
                "test",
                |mut s, _| async move {
                    let _ = s.write_all(b"yes").await;
                    let mut buf = [0u8; 1];
                    let _ = tokio::io::AsyncReadExt::read(&mut s, &mut buf).await;
                },
                |s, _| refuse(s, b"no", Duration::from_secs(1)),
            )
            .await
        });
        let answer = |mut s: TcpStream| async move {
            let mut buf = [0u8; 3];
            let n = tokio::io::AsyncReadExt::read(&mut s, &mut buf)
                .await
                .expect("reads");
            (s, buf[..n].to_vec())
        };
        let (a, first) = answer(TcpStream::connect(addr).await.expect("connects")).await;
        let (b, second) = answer(TcpStream::connect(addr).await.expect("connects")).await;
        let (_, third) = answer(TcpStream::connect(addr).await.expect("connects")).await;
        assert_eq!(
            (first.as_slice(), second.as_slice(), third.as_slice()),
            (&b"yes"[..], &b"yes"[..], &b"no"[..])
        );
        // A slot freed is taken by the next connection.
        drop(a);
        let mut next = Vec::new();
        for _ in 0..1000 {
            next = answer(TcpStream::connect(addr).await.expect("connects"))
                .await
                .1;
            if next == b"yes" {
                break;
            }
            // (The served task has not seen its peer go yet.)
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
        assert_eq!(next, b"yes");
        drop(b);
        stop.send(true).expect("the loop listens");
        server.await.expect("joins").expect("serves");
    }
}
