//! Stopping on Ctrl-C (SIGINT) or SIGTERM.

/// Ctrl-C (SIGINT) and, on Unix, SIGTERM, watched from the moment this is made (so a signal
/// that arrives while the readers start is not lost: it would end the process outright).
pub struct StopSignal {
    #[cfg(unix)]
    signals: Vec<tokio::signal::unix::Signal>,
}

impl StopSignal {
    /// Starts watching; must run inside the runtime.
    pub fn watch() -> Self {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{signal, SignalKind};
            let mut signals = Vec::new();
            for kind in [SignalKind::interrupt(), SignalKind::terminate()] {
                match signal(kind) {
                    Ok(s) => signals.push(s),
                    Err(e) => eprintln!("llrp-gateway: cannot watch a stop signal: {e}"),
                }
            }
            StopSignal { signals }
        }
        #[cfg(not(unix))]
        StopSignal {}
    }

    /// Resolves at the first of the signals.
    pub async fn wait(self) {
        #[cfg(unix)]
        {
            let mut signals = self.signals;
            if signals.is_empty() {
                let _ = tokio::signal::ctrl_c().await;
                return;
            }
            let any = std::future::poll_fn(|cx| {
                for s in &mut signals {
                    if s.poll_recv(cx).is_ready() {
                        return std::task::Poll::Ready(());
                    }
                }
                std::task::Poll::Pending
            });
            any.await;
        }
        #[cfg(not(unix))]
        let _ = tokio::signal::ctrl_c().await;
    }
}

/// Logs to standard error at `RUST_LOG`'s level (default `info`).
pub fn init_logging() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .try_init();
}
