//! The demo's live page (`spwi-sim demo --http ADDR`): plain HTML, CSS and JS shipped
//! in the binary (`sim/web/index.html`, no npm build), the floor plan at `/layout`, and
//! the fleet's state pushed as server-sent events at `/events` a few times a second.
//! Like the agent's status server, a minimal HTTP/1.1 server on tokio: three GET routes
//! do not need a framework.

use anyhow::Result;
use std::net::SocketAddr;
use std::sync::Arc;
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{broadcast, watch};

const PAGE: &str = include_str!("../web/index.html");
/// How long one server-sent-events response lasts before the browser reconnects.
const STREAM_FOR: std::time::Duration = std::time::Duration::from_secs(1);

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

/// Binds `addr`; returns the bound address and the serving future.
pub async fn serve(
    addr: SocketAddr,
    web: Arc<Web>,
    mut stop: watch::Receiver<bool>,
) -> Result<(SocketAddr, impl std::future::Future<Output = ()>)> {
    let listener = TcpListener::bind(addr).await.map_err(|e| anyhow::anyhow!("--http {addr}: {e}"))?;
    let bound = listener.local_addr()?;
    Ok((bound, async move {
        loop {
            tokio::select! {
                _ = stop.changed() => break,
                Ok((stream, _)) = listener.accept() => {
                    let (web, stop) = (web.clone(), stop.clone());
                    tokio::spawn(async move { let _ = answer(stream, web, stop).await; });
                }
            }
        }
    }))
}

async fn answer(mut stream: TcpStream, web: Arc<Web>, mut stop: watch::Receiver<bool>) -> std::io::Result<()> {
    let (_, path) = spwi_agent::http::read_request(&mut stream).await?;
    let reply = |code: &str, kind: &str, body: &str| {
        format!(
            "HTTP/1.1 {code}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        )
    };
    match path.as_str() {
        "/" | "/index.html" => stream.write_all(reply("200 OK", "text/html; charset=utf-8", PAGE).as_bytes()).await?,
        "/layout" => stream.write_all(reply("200 OK", "application/json", &web.layout).as_bytes()).await?,
        "/events" => {
            stream
                .write_all(b"HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-cache\r\nConnection: keep-alive\r\n\r\n")
                .await?;
            // Each response streams for a few seconds, then ends; the browser reconnects
            // after `retry` ms. A stream that never ends would keep headless browsers
            // (and some proxies) waiting for the page to finish loading.
            stream.write_all(b"retry: 200\n\n").await?;
            let mut rx = web.events.subscribe();
            let first = web.latest.lock().ok().and_then(|l| l.clone());
            if let Some(s) = first {
                stream.write_all(format!("data: {s}\n\n").as_bytes()).await?;
            }
            let until = tokio::time::Instant::now() + STREAM_FOR;
            loop {
                tokio::select! {
                    _ = stop.changed() => break,
                    _ = tokio::time::sleep_until(until) => break,
                    msg = rx.recv() => match msg {
                        Ok(s) => stream.write_all(format!("data: {s}\n\n").as_bytes()).await?,
                        Err(broadcast::error::RecvError::Lagged(_)) => continue,
                        Err(broadcast::error::RecvError::Closed) => break,
                    },
                }
            }
        }
        _ => stream.write_all(reply("404 Not Found", "text/plain", "not found\n").as_bytes()).await?,
    }
    stream.shutdown().await
}
