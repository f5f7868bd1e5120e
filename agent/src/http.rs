//! `/healthz`, `/status` (JSON) and `/metrics` (Prometheus text) over plain HTTP/1.1.
//!
//! Three read-only GET routes do not justify a web framework's build time on the
//! robots' small CPUs: this is a minimal server on tokio's TcpListener that reads one
//! request, answers it and closes the connection.

use crate::status::SharedStatus;
use anyhow::Result;
use std::net::SocketAddr;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;
use tokio::sync::watch;

/// Binds `addr` and returns the bound address and the serving future.
pub async fn serve(
    addr: SocketAddr,
    status: SharedStatus,
    mut shutdown: watch::Receiver<bool>,
) -> Result<(SocketAddr, impl std::future::Future<Output = ()>)> {
    let listener = TcpListener::bind(addr).await.map_err(|e| anyhow::anyhow!("http.listen {addr}: {e}"))?;
    let bound = listener.local_addr()?;
    let fut = async move {
        loop {
            tokio::select! {
                _ = shutdown.changed() => break,
                accepted = listener.accept() => {
                    let Ok((stream, _)) = accepted else { continue };
                    let status = status.clone();
                    tokio::spawn(async move {
                        let _ = tokio::time::timeout(std::time::Duration::from_secs(5), answer(stream, status)).await;
                    });
                }
            }
        }
    };
    Ok((bound, fut))
}

/// Reads a request head (at most 4 KiB) and returns its method and path.
pub async fn read_request(stream: &mut tokio::net::TcpStream) -> std::io::Result<(String, String)> {
    let mut buf = vec![0u8; 4096];
    let mut n = 0;
    while n < buf.len() {
        let m = stream.read(&mut buf[n..]).await?;
        n += m;
        if m == 0 || buf[..n].windows(4).any(|w| w == b"\r\n\r\n") {
            break;
        }
    }
    let request = String::from_utf8_lossy(&buf[..n]);
    let mut words = request.split_whitespace();
    Ok((words.next().unwrap_or("").to_owned(), words.next().unwrap_or("").to_owned()))
}

async fn answer(mut stream: tokio::net::TcpStream, status: SharedStatus) -> std::io::Result<()> {
    let (method, path) = read_request(&mut stream).await?;
    let (code, kind, body) = match (method.as_str(), path.as_str()) {
        ("GET", "/healthz") => (200, "text/plain", "ok\n".to_owned()),
        ("GET", "/status") => {
            let s = status.lock().map(|s| serde_json::to_string_pretty(&*s)).unwrap_or_else(|_| Ok("{}".into()));
            (200, "application/json", s.unwrap_or_default())
        }
        ("GET", "/metrics") => {
            let text = status.lock().map(|s| s.prometheus()).unwrap_or_default();
            (200, "text/plain; version=0.0.4", text)
        }
        ("GET", _) => (404, "text/plain", "not found: try /healthz, /status or /metrics\n".to_owned()),
        _ => (405, "text/plain", "only GET is served\n".to_owned()),
    };
    let reason = match code {
        200 => "OK",
        404 => "Not Found",
        _ => "Method Not Allowed",
    };
    let head = format!(
        "HTTP/1.1 {code} {reason}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes()).await?;
    stream.write_all(body.as_bytes()).await?;
    stream.shutdown().await
}
