//! Starting the HTTP API beside a command (`sim`, `proxy`, `replay`): the `--http` options,
//! binding (a default address that is taken is reported and skipped; an address the user
//! gave must bind), the token rule, and stopping.

use std::net::SocketAddr;
use std::sync::Arc;

use tokio::sync::oneshot;
use tokio::task::JoinHandle;

use super::{
    check_bind, require_token_everywhere, router, serve, BrowserRules, HttpOptions, ServerLimits,
    DEFAULT_BODY_LIMIT,
};
use crate::localize::live::Tap;
use crate::localize::shared::Shared;
use crate::metrics::Metrics;
use crate::secret::Secret;

/// How the HTTP API beside a command is served (the command line's `--http` options).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LaunchOptions {
    /// Serve the HTTP API and live map here (`127.0.0.1:0` picks a free port; the bound
    /// address is printed). Beyond loopback it needs `--http-token`.
    pub http: Option<String>,
    /// No HTTP API.
    pub no_http: bool,
    /// Bearer token the write routes need (every route when bound beyond loopback); shown as
    /// `***`.
    pub http_token: Option<Secret>,
    /// A host name the loopback HTTP API also answers to (beside localhost, 127.0.0.1 and
    /// `[::1]`); `.example.lan` takes a domain and its subdomains. Repeatable.
    pub http_allowed_host: Vec<String>,
    /// An origin whose pages may call the HTTP API, writes included (CORS), e.g.
    /// `http://dashboard.lan:3000`. Repeatable.
    pub http_allowed_origin: Vec<String>,
}

impl LaunchOptions {
    /// The browser rules these flags give a listener on `bound`.
    pub fn browser(&self, bound: &SocketAddr) -> BrowserRules {
        BrowserRules {
            check_host: !require_token_everywhere(bound),
            allowed_hosts: self.http_allowed_host.clone(),
            allowed_origins: self.http_allowed_origin.clone(),
        }
    }

    /// Where to serve, and whether the user chose it: `default` when no `--http` was given
    /// (`None`: off unless asked for), nothing with `--no-http`.
    pub fn address(&self, default: Option<&str>) -> Option<(String, bool)> {
        if self.no_http {
            return None;
        }
        match &self.http {
            Some(a) => Some((a.clone(), true)),
            None => default.map(|d| (d.to_string(), false)),
        }
    }
}

/// Why the HTTP API did not start.
#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    /// The address is not `HOST:PORT`.
    #[error("--http {addr}: not an address (HOST:PORT): {reason}")]
    Address {
        /// The address.
        addr: String,
        /// Why.
        reason: String,
    },
    /// Beyond loopback without a token.
    #[error("--http {addr}: {reason}")]
    Exposed {
        /// The address.
        addr: String,
        /// Why.
        reason: String,
    },
    /// The address could not be bound.
    #[error("--http {addr}: cannot listen: {source}")]
    Bind {
        /// The address.
        addr: String,
        /// Why.
        source: std::io::Error,
    },
}

/// A running HTTP API.
pub struct Launched {
    /// The bound address.
    pub addr: SocketAddr,
    stop: oneshot::Sender<()>,
    task: JoinHandle<std::io::Result<()>>,
}

impl Launched {
    /// Stops serving: open event streams end, requests under way finish.
    pub async fn stop(self) {
        let _ = self.stop.send(());
        match tokio::time::timeout(std::time::Duration::from_secs(2), self.task).await {
            Ok(Ok(Ok(()))) => {}
            Ok(Ok(Err(e))) => tracing::warn!("the HTTP API ended with an error: {e}"),
            Ok(Err(e)) => tracing::warn!("the HTTP API's task failed: {e}"),
            Err(_) => tracing::warn!("the HTTP API did not stop within 2 s"),
        }
    }
}

/// Starts the API on `addr` over `shared` and `tap`, serving `metrics` at `/metrics`, with
/// the token and browser rules of `args`. When `chosen` is false (the command's default
/// address) and the address is taken, `Ok(None)`: the caller says so and runs on.
#[allow(clippy::too_many_arguments)]
pub async fn launch(
    addr: &str,
    chosen: bool,
    args: &LaunchOptions,
    simulation: bool,
    shared: Arc<Shared>,
    tap: Tap,
    metrics: Arc<Metrics>,
    gpio: Option<Arc<dyn super::gpio::GpioControl>>,
    faults: Option<Arc<dyn super::faults::FaultControl>>,
) -> Result<Option<Launched>, LaunchError> {
    let listener = match tokio::net::TcpListener::bind(addr).await {
        Ok(l) => l,
        Err(e) if !chosen && e.kind() == std::io::ErrorKind::AddrInUse => return Ok(None),
        Err(source) => {
            return Err(LaunchError::Bind {
                addr: addr.to_string(),
                source,
            })
        }
    };
    let bound = listener.local_addr().map_err(|source| LaunchError::Bind {
        addr: addr.to_string(),
        source,
    })?;
    let token = args.http_token.clone();
    check_bind(&bound, &token).map_err(|reason| LaunchError::Exposed {
        addr: addr.to_string(),
        reason,
    })?;
    let options = HttpOptions {
        token,
        token_everywhere: require_token_everywhere(&bound),
        simulation,
        body_limit: DEFAULT_BODY_LIMIT,
        limits: ServerLimits::default(),
        browser: args.browser(&bound),
        metrics: Some(metrics),
        gpio,
        faults,
    };
    let limits = options.limits;
    let app = router(shared, tap, options);
    let (stop, stopped) = oneshot::channel::<()>();
    let task = tokio::spawn(serve(listener, app, limits, async move {
        let _ = stopped.await;
    }));
    Ok(Some(Launched {
        addr: bound,
        stop,
        task,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_applies_only_without_http_and_no_http_turns_it_off() {
        let args = |http: Option<&str>, no_http| LaunchOptions {
            http: http.map(String::from),
            no_http,
            http_token: None,
            ..LaunchOptions::default()
        };
        let d = Some("127.0.0.1:8080");
        assert_eq!(
            args(None, false).address(d),
            Some(("127.0.0.1:8080".into(), false))
        );
        assert_eq!(args(None, false).address(None), None);
        assert_eq!(
            args(Some("127.0.0.1:0"), false).address(None),
            Some(("127.0.0.1:0".into(), true))
        );
        assert_eq!(args(None, true).address(d), None);
    }

    #[tokio::test]
    async fn a_taken_default_is_skipped_and_a_taken_choice_is_an_error() {
        let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("binds");
        let addr = taken.local_addr().expect("bound").to_string();
        let live = crate::localize::live::Live::start(Default::default()).expect("starts");
        let skipped = launch(
            &addr,
            false,
            &LaunchOptions::default(),
            false,
            live.shared.clone(),
            live.tap.clone(),
            crate::metrics::Metrics::of_localizer(&live.shared),
            None,
            None,
        )
        .await
        .expect("a taken default is no error");
        assert!(skipped.is_none());
        let err = launch(
            &addr,
            true,
            &LaunchOptions::default(),
            false,
            live.shared.clone(),
            live.tap.clone(),
            crate::metrics::Metrics::of_localizer(&live.shared),
            None,
            None,
        )
        .await
        .err()
        .expect("a taken choice is an error");
        assert!(
            err.to_string().contains(&addr) && err.to_string().contains("cannot listen"),
            "{err}"
        );
        live.stop();
    }
}
