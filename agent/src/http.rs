//! `/healthz`, `/status` (JSON) and `/metrics` (OpenMetrics text), served by axum over
//! HTTP/1.1 on the daemon's tokio runtime: keep-alive, HEAD, 404 for unknown paths and
//! 405 for other methods come with it. The handlers only read the snapshot the event
//! loop refreshes once per decision.

use crate::status::SharedStatus;
use anyhow::Result;
use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::IntoResponse;
use axum::routing::get;
use axum::Router;
use std::net::SocketAddr;
use tokio::net::TcpListener;
use tokio::sync::watch;

/// Binds `addr` and returns the bound address and the serving future, which ends when
/// `shutdown` changes.
pub async fn serve(
    addr: SocketAddr,
    status: SharedStatus,
    mut shutdown: watch::Receiver<bool>,
) -> Result<(SocketAddr, impl std::future::Future<Output = ()>)> {
    let listener = TcpListener::bind(addr).await.map_err(|e| anyhow::anyhow!("http.listen {addr}: {e}"))?;
    let bound = listener.local_addr()?;
    let app = Router::new()
        .route("/healthz", get(healthz))
        .route("/status", get(status_json))
        .route("/metrics", get(metrics))
        .fallback(|| async { (StatusCode::NOT_FOUND, "not found: try /healthz, /status or /metrics\n") })
        .with_state(status);
    let fut = async move {
        let stop = async move {
            let _ = shutdown.changed().await;
        };
        if let Err(e) = axum::serve(listener, app).with_graceful_shutdown(stop).await {
            tracing::warn!("http server on {bound} stopped: {e}");
        }
    };
    Ok((bound, fut))
}

/// 200 "ok", or 503 and the reason when frames arrive but no tick gets decided.
async fn healthz(State(status): State<SharedStatus>) -> impl IntoResponse {
    let problem = status.lock().ok().and_then(|s| s.health.check(std::time::Instant::now()));
    match problem {
        None => (StatusCode::OK, "ok\n".to_owned()),
        Some(p) => (StatusCode::SERVICE_UNAVAILABLE, format!("unhealthy: {p}\n")),
    }
}

async fn status_json(State(status): State<SharedStatus>) -> impl IntoResponse {
    let body = status.lock().map(|s| serde_json::to_string_pretty(&*s)).unwrap_or_else(|_| Ok("{}".into()));
    ([(header::CONTENT_TYPE, "application/json")], body.unwrap_or_default())
}

async fn metrics(State(status): State<SharedStatus>) -> impl IntoResponse {
    let text = status.lock().map(|s| s.prometheus()).unwrap_or_default();
    ([(header::CONTENT_TYPE, "application/openmetrics-text; version=1.0.0; charset=utf-8")], text)
}
