//! A small lossy network of Linux network namespaces, for process tests that need real
//! packets dropped on real links (root only; `tc netem` is missing on the machines this
//! runs on, iptables' `statistic` match is not).
//!
//! Each robot gets a namespace of its own with one interface, `eth0`, on a bridge that
//! lives in a switch namespace; the test process reaches the bridge from the host
//! namespace through one more veth, as the robots' camera feed and the observer. So
//! robots talk to each other across their own interfaces, exactly what the drop rules
//! act on, and nothing touches the host's firewall (Docker's included): every rule is
//! in a namespace this module creates and removes.

use anyhow::{bail, Context, Result};
use std::process::Command;

/// The host side's address on the bridge (the hub, i.e. the world and the observer).
pub const HOST_ADDRESS: &str = "10.211.0.1";
const SUBNET: &str = "10.211.0.0";
const PREFIX_LEN: u8 = 24;

/// Namespaces, veths and a bridge, removed on drop.
pub struct LossyNetwork {
    tag: String,
    robots: usize,
}

impl LossyNetwork {
    /// Why this machine cannot build one (not root, no `ip` or `iptables`), if so.
    pub fn unavailable() -> Option<String> {
        let uid = Command::new("id").arg("-u").output().map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned());
        if uid.as_deref().unwrap_or("") != "0" {
            return Some("needs root".into());
        }
        for tool in ["ip", "iptables"] {
            if Command::new(tool).arg("-V").output().is_err() {
                return Some(format!("needs {tool}"));
            }
        }
        None
    }

    /// Creates a switch and `robots` robot namespaces attached to it. `rto_min` (e.g.
    /// "5ms") sets the robots' route's minimum TCP retransmission timeout (Linux: 200 ms),
    /// as an operator can on lossy links.
    pub fn create(robots: usize, rto_min: Option<&str>) -> Result<LossyNetwork> {
        assert!(robots < 200, "one /24 holds the robots");
        remove_stale()?;
        let net = LossyNetwork { tag: format!("spwi{}", std::process::id()), robots };
        let sw = net.switch();
        ip(&["netns", "add", &sw])?;
        ns(&sw, &["ip", "link", "add", "br0", "type", "bridge"])?;
        ns(&sw, &["ip", "link", "set", "br0", "up"])?;
        // The host's leg: its end keeps a name of this test's own.
        let host = format!("{}h", net.tag); // also in drop
        ip(&["link", "add", &host, "type", "veth", "peer", "name", "host", "netns", &sw])?;
        ip(&["addr", "add", &format!("{HOST_ADDRESS}/{PREFIX_LEN}"), "dev", &host])?;
        ip(&["link", "set", &host, "up"])?;
        ns(&sw, &["ip", "link", "set", "host", "master", "br0", "up"])?;
        for i in 0..robots {
            let (name, port) = (net.namespace(i), format!("r{i}"));
            ip(&["netns", "add", &name])?;
            ns(&sw, &["ip", "link", "add", &port, "type", "veth", "peer", "name", "eth0", "netns", &name])?;
            ns(&sw, &["ip", "link", "set", &port, "master", "br0", "up"])?;
            ns(&name, &["ip", "addr", "add", &format!("{}/{PREFIX_LEN}", net.address(i)), "dev", "eth0"])?;
            ns(&name, &["ip", "link", "set", "eth0", "up"])?;
            ns(&name, &["ip", "link", "set", "lo", "up"])?;
            if let Some(rto) = rto_min {
                let subnet = format!("{}/{PREFIX_LEN}", SUBNET);
                ns(&name, &["ip", "route", "replace", &subnet, "dev", "eth0", "rto_min", rto])?;
            }
        }
        Ok(net)
    }

    /// Robot `i`'s namespace (for `ip netns exec`).
    pub fn namespace(&self, i: usize) -> String {
        format!("{}r{i}", self.tag)
    }

    /// Robot `i`'s address on the bridge.
    pub fn address(&self, i: usize) -> String {
        format!("10.211.0.{}", 10 + i)
    }

    /// A command that runs `program` inside robot `i`'s namespace.
    pub fn command(&self, i: usize, program: &str) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.namespace(i), program]);
        c
    }

    /// Drops each packet reaching a robot from another robot with `probability` (0
    /// removes the rules). Packets from the host (the camera feed and the observer) are
    /// kept: on a real robot the camera is not behind the radio link.
    pub fn drop_between_robots(&self, probability: f64) -> Result<()> {
        for i in 0..self.robots {
            let name = self.namespace(i);
            ns(&name, &["iptables", "-F", "INPUT"])?;
            if probability > 0.0 {
                let p = probability.to_string();
                ns(
                    &name,
                    &[
                        "iptables",
                        "-A",
                        "INPUT",
                        "-i",
                        "eth0",
                        "!",
                        "-s",
                        HOST_ADDRESS,
                        "-m",
                        "statistic",
                        "--mode",
                        "random",
                        "--probability",
                        &p,
                        "-j",
                        "DROP",
                    ],
                )?;
            }
        }
        Ok(())
    }

    fn switch(&self) -> String {
        format!("{}sw", self.tag)
    }
}

impl Drop for LossyNetwork {
    /// Deleting a namespace deletes its interfaces, and with them their veth peers, but
    /// the kernel does it later: the host's leg is deleted at once.
    fn drop(&mut self) {
        let _ = ip(&["link", "del", &format!("{}h", self.tag)]);
        for i in 0..self.robots {
            let _ = ip(&["netns", "del", &self.namespace(i)]);
        }
        let _ = ip(&["netns", "del", &self.switch()]);
    }
}

/// Removes the namespaces of earlier runs whose process is gone (a test killed before
/// its drop ran would otherwise leave the host a second leg with the same address).
fn remove_stale() -> Result<()> {
    let out = Command::new("ip").args(["netns", "list"]).output().context("running ip netns list")?;
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let name = line.split_whitespace().next().unwrap_or("");
        let Some(rest) = name.strip_prefix("spwi") else { continue };
        let pid: String = rest.chars().take_while(char::is_ascii_digit).collect();
        if !pid.is_empty() && !std::path::Path::new(&format!("/proc/{pid}")).exists() {
            ip(&["netns", "del", name])?;
        }
    }
    Ok(())
}

fn ip(args: &[&str]) -> Result<()> {
    run(Command::new("ip").args(args))
}

fn ns(name: &str, args: &[&str]) -> Result<()> {
    run(Command::new("ip").args(["netns", "exec", name]).args(args))
}

fn run(c: &mut Command) -> Result<()> {
    let out = c.output().with_context(|| format!("running {c:?}"))?;
    if !out.status.success() {
        bail!("{c:?} failed: {}", String::from_utf8_lossy(&out.stderr).trim());
    }
    Ok(())
}
