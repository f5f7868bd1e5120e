//! `spwi-router` processes for a loopback fleet whose robots are Zenoh clients of
//! routers instead of a peer mesh (`spwi-sim bench --routers N`). A full mesh of N
//! robots is N·(N−1)/2 links, each robot sending every message once per peer; as a
//! client a robot has one link and sends each message once, and the router fans it
//! out. Each router listens on a free loopback port and connects to every router
//! started before it, so the routers form a full mesh: a client of any of them reaches
//! every robot, and no single router's death splits the others. A client lists its
//! home router first and the others after it, so when its router goes down it
//! connects to the next.

use anyhow::{bail, Context, Result};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub struct Routers {
    /// Where each router listens (`tcp/127.0.0.1:PORT`).
    pub endpoints: Vec<String>,
    /// One per router; `None` once it was killed.
    processes: Vec<Option<Child>>,
}

impl Routers {
    /// Starts `n` routers from the `spwi-router` binary `binary` and waits until each
    /// accepts connections (a Zenoh client that finds no router at start gives up).
    pub fn start(binary: &Path, n: usize) -> Result<Routers> {
        if !binary.is_file() {
            bail!("{}: no spwi-router binary there (cargo build --release builds it)", binary.display());
        }
        let mut routers = Routers { endpoints: Vec::new(), processes: Vec::new() };
        for i in 0..n {
            let port = free_port()?;
            let endpoint = format!("tcp/127.0.0.1:{port}");
            let mut command = Command::new(binary);
            command
                .args(["--listen", &endpoint, "--cfg", "scouting/multicast/enabled:false"])
                .env("RUST_LOG", "warn,zenoh=error")
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::null());
            if i > 0 {
                command.args(["--cfg", &format!("connect/endpoints:{}", serde_json::to_string(&routers.endpoints)?)]);
            }
            let child = command.spawn().with_context(|| format!("starting {}", binary.display()))?;
            routers.processes.push(Some(child));
            wait_listening(port, Duration::from_secs(10)).with_context(|| format!("router {i} on {endpoint}"))?;
            routers.endpoints.push(endpoint);
        }
        Ok(routers)
    }

    /// What a client whose home router is `home` connects to: that router, then the
    /// others in turn (Zenoh's client takes the first it reaches).
    pub fn connect_from(&self, home: usize) -> Vec<String> {
        let n = self.endpoints.len();
        (0..n).map(|k| self.endpoints[(home + k) % n].clone()).collect()
    }

    /// CPU seconds (user and system) the routers still running have used.
    pub fn cpu_s(&self) -> f64 {
        self.processes.iter().flatten().filter_map(|c| super::usage(c.id())).map(|u| u.cpu_s).sum()
    }

    /// Kills router `i` at once (SIGKILL: a crash or a power cut, no goodbye).
    pub fn kill(&mut self, i: usize) -> Result<()> {
        let mut child = self.processes[i].take().with_context(|| format!("router {i} is not running"))?;
        child.kill()?;
        child.wait()?;
        Ok(())
    }
}

impl Drop for Routers {
    fn drop(&mut self) {
        for child in self.processes.iter_mut().flatten() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// A loopback port nothing listens on now (the OS's pick; free again when returned).
fn free_port() -> Result<u16> {
    Ok(TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

fn wait_listening(port: u16, limit: Duration) -> Result<()> {
    let since = Instant::now();
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        if since.elapsed() > limit {
            bail!("not listening within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_client_tries_its_home_router_first_then_the_others() {
        let r = Routers { endpoints: vec!["a".into(), "b".into(), "c".into()], processes: Vec::new() };
        assert_eq!(r.connect_from(0), ["a", "b", "c"]);
        assert_eq!(r.connect_from(2), ["c", "a", "b"]);
    }

    #[test]
    fn a_missing_binary_is_named() {
        let e = Routers::start(Path::new("/nonexistent/spwi-router"), 1).err().unwrap().to_string();
        assert!(e.contains("/nonexistent/spwi-router"), "{e}");
    }
}
