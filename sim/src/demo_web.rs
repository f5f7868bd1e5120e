//! The demo's live page (`spwi-sim demo --http ADDR`): plain HTML, CSS and JS shipped
//! in the binary (`sim/web/index.html`, no npm build), the floor plan at `/layout`, and
//! the fleet's state pushed as server-sent events at `/events` a few times a second.
//! Served by axum, like the agent's status endpoints.

use anyhow::Result;
use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::sse::{Event, Sse};
use axum::response::{Html, IntoResponse};
use axum::routing::get;
use axum::Router;
use futures_util::stream::{self, StreamExt};
use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::{broadcast, watch};

const PAGE: &str = include_str!("../web/index.html");
/// How long one server-sent-events response lasts before the browser reconnects.
const STREAM_FOR: Duration = Duration::from_secs(1);
/// How soon the browser reconnects after a response ends.
const RECONNECT: Duration = Duration::from_millis(200);

/// Shared between the demo loop (publisher) and the connections.
pub struct Web {
    layout: String,
    events: broadcast::Sender<Arc<String>>,
    latest: std::sync::Mutex<Option<Arc<String>>>,
}

impl Web {
    pub fn new(layout_json: String) -> Arc<Web> {
        let (events, _) = broadcast::channel(16);
        Arc::new(Web { layout: layout_json, events, latest: std::sync::Mutex::new(None) })
    }

    /// Sends a state (JSON) to every open page.
    pub fn publish(&self, state: String) {
        let s = Arc::new(state);
        if let Ok(mut l) = self.latest.lock() {
            *l = Some(s.clone());
        }
        let _ = self.events.send(s);
    }
}

/// Binds `addr`; returns the bound address and the serving future, which ends when
/// `stop` changes.
pub async fn serve(
    addr: SocketAddr,
    web: Arc<Web>,
    mut stop: watch::Receiver<bool>,
) -> Result<(SocketAddr, impl std::future::Future<Output = ()>)> {
    let listener = TcpListener::bind(addr).await.map_err(|e| anyhow::anyhow!("--http {addr}: {e}"))?;
    let bound = listener.local_addr()?;
    let app = Router::new()
        .route("/", get(|| async { Html(PAGE) }))
        .route("/index.html", get(|| async { Html(PAGE) }))
        .route(
            "/layout",
            get(|State(web): State<Arc<Web>>| async move {
                ([(header::CONTENT_TYPE, "application/json")], web.layout.clone())
            }),
        )
        .route("/events", get(events))
        .fallback(|| async { (StatusCode::NOT_FOUND, "not found\n") })
        .with_state(web);
    Ok((bound, async move {
        let stop = async move {
            let _ = stop.changed().await;
        };
        if let Err(e) = axum::serve(listener, app).with_graceful_shutdown(stop).await {
            tracing::warn!("demo page server on {bound} stopped: {e}");
        }
    }))
}

/// The latest state, then every new one for [`STREAM_FOR`]; then the response ends and
/// the browser reconnects. A stream that never ends would keep headless browsers (and
/// some proxies) waiting for the page to finish loading.
async fn events(State(web): State<Arc<Web>>) -> impl IntoResponse {
    let until = tokio::time::Instant::now() + STREAM_FOR;
    let latest = web.latest.lock().ok().and_then(|l| l.clone());
    let head = stream::iter(std::iter::once(Event::default().retry(RECONNECT)).chain(latest.map(data)));
    let live = stream::unfold(web.events.subscribe(), move |mut rx| async move {
        loop {
            match tokio::time::timeout_at(until, rx.recv()).await.ok()? {
                Ok(s) => return Some((data(s), rx)),
                Err(broadcast::error::RecvError::Lagged(_)) => continue,
                Err(broadcast::error::RecvError::Closed) => return None,
            }
        }
    });
    Sse::new(head.chain(live).map(Ok::<_, Infallible>))
}

fn data(state: Arc<String>) -> Event {
    Event::default().data(state.as_str())
}
