//! The live localizer beside `proxy`, `replay` and `inventory`: its settings from a settings
//! file and the poses known at start ([`settings_from`]), and the proxy's tapped reads, events
//! and keepalive links handed to it ([`forward`]). The command-line side (the options, the
//! localizer and publisher started through `cli::root`) is `cli::live`.

use crate::reads::ReaderName;
use std::time::{Duration, Instant};

use crate::localize::estimate::Estimator;
use crate::localize::live::{Input, Settings, Tap};
use crate::localize::offline::{geometry, SettingsFile};
use crate::localize::poses::Poses;
use crate::localize::series::Ambiguity;
use crate::net::proxy::keepalive::{self, Change, Links};
use crate::net::proxy::Tapped;
use llrp_gateway_vocab::feed::Inventory;
use prometheus_client::metrics::counter::Counter;

/// The live localizer's settings from a settings file and the poses known at start (with
/// none, derived from each reader's first pose as it comes).
pub fn settings_from(file: &SettingsFile, poses: &Poses, estimator: Estimator) -> Settings {
    Settings {
        derive_geometry: poses.is_empty().then(|| file.clone()),
        estimator,
        geometry: geometry(file, &[], poses),
        ambiguity: if file.pi_ambiguity {
            Ambiguity::Pi
        } else {
            Ambiguity::None
        },
        min_rssi_dbm: file.min_rssi_dbm,
        ..Settings::default()
    }
}

/// How often the proxy's keepalive links are looked at.
const LINK_POLL: Duration = Duration::from_millis(50);

/// Hands the proxy's tapped reads and events to the localizer (and its mirrors) until the
/// proxy's tap closes, and watches its sessions' keepalive links (`links`): a link lost or
/// restored is logged, counted in `losses` and handed on as [`Input::Keepalive`].
pub async fn forward(
    mut rx: tokio::sync::mpsc::Receiver<Tapped>,
    links: Links,
    tap: Tap,
    losses: Counter,
) {
    let mut poll = tokio::time::interval(LINK_POLL);
    poll.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            t = rx.recv() => match t {
                Some(t) => forward_one(t, &tap),
                None => return,
            },
            _ = poll.tick() => {
                for (reader, change) in links.poll(Instant::now()) {
                    keepalive_change(&tap, &losses, &reader, change);
                }
            }
        }
    }
}

/// Logs, counts and hands on a change of `reader`'s keepalive link.
fn keepalive_change(tap: &Tap, losses: &Counter, reader: &ReaderName, change: Change) {
    let ms = |d: Duration| u64::try_from(d.as_millis()).unwrap_or(u64::MAX);
    let (lost, period, silent) = match change {
        Change::Lost { period, silent } => {
            losses.inc();
            tracing::warn!(
                reader = %reader,
                period_ms = ms(period),
                "no KEEPALIVE for {} periods: the reader's link is taken for lost",
                keepalive::MISSES
            );
            (true, period, silent)
        }
        Change::Restored { period, silent } => {
            tracing::info!(
                reader = %reader,
                silent_ms = ms(silent),
                "KEEPALIVEs again: the reader's link is back"
            );
            (false, period, silent)
        }
    };
    tap.offer(Input::Keepalive {
        reader: reader.clone(),
        lost,
        period_ms: ms(period),
        silent_ms: ms(silent),
    });
}

/// Hands one tapped report or event on.
fn forward_one(t: Tapped, tap: &Tap) {
    match t {
        Tapped::Reads(reads) => {
            tap.offer(Input::Reads(reads));
        }
        Tapped::Event {
            reader, message, ..
        } => {
            let llrp::MessageBody::ReaderEventNotification(n) = &message.body else {
                return;
            };
            let data = &n.reader_event_notification_data;
            tap.offer(Input::Event {
                reader: reader.clone(),
                data: Box::new(data.clone()),
            });
            let connected = if data.connection_close_event.is_some() {
                Some(false)
            } else {
                data.connection_attempt_event
                    .as_ref()
                    .map(|e| e.status == llrp::enums::ConnectionAttemptStatus::Success)
            };
            if let Some(c) = connected {
                tap.offer(Input::Status {
                    reader: reader.clone(),
                    online: c,
                });
                tap.links().update(&reader, |l| {
                    l.connected = c;
                    l.inventory = if c {
                        Inventory::Client
                    } else {
                        Inventory::Idle
                    };
                });
            }
        }
    }
}
