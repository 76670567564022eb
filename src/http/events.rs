//! `GET /api/events`: estimate updates as Server-Sent Events.

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::State;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::Extension;
use futures_util::stream::{self, Stream};
use tokio::sync::broadcast::error::RecvError;
use tokio::sync::{broadcast, watch};

use super::{AppState, Closing};
use crate::localize::shared::{TagJson, TagView};

/// Keep-alive comments are sent this often while no event comes.
pub const KEEP_ALIVE: Duration = Duration::from_secs(15);

/// What the stream sends next.
#[derive(Debug, PartialEq)]
enum Update {
    /// The opening comment, at once, so the client knows it is subscribed.
    Subscribed,
    /// A tag's new estimate, as `GET /api/tags` writes it.
    Estimate(String),
    /// This subscriber fell behind and missed this many updates.
    Lagged(u64),
}

impl Update {
    fn event(self) -> Event {
        match self {
            Update::Subscribed => Event::default().comment("subscribed"),
            Update::Estimate(data) => Event::default().event("estimate").data(data),
            Update::Lagged(missed) => Event::default()
                .event("lagged")
                .data(serde_json::json!({ "missed": missed }).to_string()),
        }
    }
}

/// What the stream waits on: the subscription and, when served by [`super::serve`], the
/// shutdown signal.
struct Feed {
    rx: broadcast::Receiver<Arc<TagView>>,
    closing: Option<watch::Receiver<bool>>,
    /// The opening comment is still to be sent.
    opened: bool,
}

async fn closed(closing: &mut Option<watch::Receiver<bool>>) {
    match closing {
        // Resolves when it turns true or the server is gone.
        Some(rx) => {
            let _ = rx.wait_for(|c| *c).await;
        }
        None => std::future::pending().await,
    }
}

/// The next update; `None` when the server shuts down or the localizer is gone.
async fn next_update(feed: &mut Feed) -> Option<Update> {
    if !feed.opened {
        feed.opened = true;
        return Some(Update::Subscribed);
    }
    let next = tokio::select! {
        _ = closed(&mut feed.closing) => return None,
        next = feed.rx.recv() => next,
    };
    match next {
        Ok(view) => {
            // Plain strings and finite numbers (serde_json writes null for a NaN).
            let data = serde_json::to_string(&TagJson::from(&*view)).unwrap_or_default();
            Some(Update::Estimate(data))
        }
        Err(RecvError::Lagged(missed)) => Some(Update::Lagged(missed)),
        Err(RecvError::Closed) => None,
    }
}

fn feed(feed: Feed) -> impl Stream<Item = Result<Event, Infallible>> {
    stream::unfold(feed, |mut feed| async move {
        let update = next_update(&mut feed).await?;
        Some((Ok(update.event()), feed))
    })
}

#[utoipa::path(get, path = "/api/events", tag = "localizer",
    responses((status = 200, description = "Server-Sent Events: `estimate` (data: one tag as in \
        /api/tags) per estimate update; `lagged` (data: {\"missed\": n}) when this subscriber \
        fell behind and missed n updates; keep-alive comments", content_type = "text/event-stream")))]
pub(super) async fn events(
    State(state): State<AppState>,
    closing: Option<Extension<Closing>>,
) -> Sse<impl Stream<Item = Result<Event, Infallible>>> {
    let start = Feed {
        rx: state.events.subscribe(),
        closing: closing.map(|Extension(Closing(rx))| rx),
        opened: false,
    };
    Sse::new(feed(start)).keep_alive(KeepAlive::new().interval(KEEP_ALIVE).text("keep-alive"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(epc: &str) -> Arc<TagView> {
        Arc::new(TagView::unseen(epc, "relock"))
    }

    #[tokio::test]
    async fn a_lagging_subscriber_is_told_how_many_it_missed_then_goes_on() {
        let (tx, rx) = broadcast::channel(2);
        let (closing_tx, closing_rx) = watch::channel(false);
        let mut feed = Feed {
            rx,
            closing: Some(closing_rx),
            opened: false,
        };
        assert_eq!(next_update(&mut feed).await, Some(Update::Subscribed));
        for epc in ["A1", "A2", "A3", "A4", "A5"] {
            tx.send(view(epc)).expect("a subscriber");
        }
        assert_eq!(next_update(&mut feed).await, Some(Update::Lagged(3)));
        match next_update(&mut feed).await {
            Some(Update::Estimate(data)) => {
                let v: serde_json::Value = serde_json::from_str(&data).expect("JSON");
                assert_eq!(v["epc"], "A4");
                assert_eq!(v["state"], "insufficient_geometry");
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            next_update(&mut feed).await,
            Some(Update::Estimate(_))
        ));
        // Shutting down ends the stream.
        closing_tx.send(true).expect("the feed listens");
        assert_eq!(next_update(&mut feed).await, None);
    }
}
