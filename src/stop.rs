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

/// How log lines are written (`--log-format`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LogFormat {
    /// One line of text an event; coloured on a terminal unless `NO_COLOR` is set.
    #[default]
    Text,
    /// One JSON object an event (for services and log collectors); never coloured.
    Json,
}

static LOG_FORMAT: std::sync::OnceLock<LogFormat> = std::sync::OnceLock::new();

/// Chooses the log format for [`init_logging`] (the first choice stands).
pub fn set_log_format(format: LogFormat) {
    let _ = LOG_FORMAT.set(format);
}

/// Whether text logs to standard error get colours: on a terminal, and `NO_COLOR` unset or
/// empty (no-color.org).
pub fn log_colours() -> bool {
    use std::io::IsTerminal;
    std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty())
}

/// Logs to standard error at `RUST_LOG`'s level (default `info`), in the format
/// [`set_log_format`] chose.
pub fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    let _ = match LOG_FORMAT.get().copied().unwrap_or_default() {
        LogFormat::Text => builder.with_ansi(log_colours()).try_init(),
        LogFormat::Json => builder.json().with_ansi(false).try_init(),
    };
}
