//! Zenoh settings, shared by the agent and the simulated world: Zenoh's own json5 file
//! (`--zenoh-config`, as `zenohd` takes it), then `--cfg KEY:VALUE` overrides.
//!
//! Without a file, spwi sets what membership needs: a 1000 ms link lease with
//! keep-alive 4. A peer that is killed is seen at once (its TCP links close), but one
//! that freezes, loses power or is unplugged is only seen when its lease runs out, so
//! this bounds how long a silent robot stays in the vote (≈ 1 s). The departed peer's
//! own lease is what counts: every robot must run the same one.
//!
//! It also gives each link's data queue [`DATA_QUEUE_BATCHES`] batches instead of
//! Zenoh's 2. A robot's tick ends in a burst of messages (its share, relayed ballots,
//! decision), and Zenoh drops a message that finds no free batch within 1 ms: on a
//! busy host, where the link's sending task is not scheduled that soon, two batches
//! lose messages of the burst (docs/BENCHMARKS.md, "Soak", measures how many).
//! Messages that are not express share a batch when the link lags
//! (`daemon/publishing.rs`), so they need fewer; the margin stays.
//!
//! A router carries every client's burst on each of its links: with 16 robots as its
//! clients, a tick puts some fifty messages on every outgoing link at once. So
//! [`build_router`] gives its links Zenoh's largest data queue ([`ROUTER_DATA_QUEUE_BATCHES`])
//! and lets a message wait up to [`ROUTER_WAIT_BEFORE_DROP_US`] for a free batch instead of
//! 1 ms: with the agents' settings, a router serving many robots on a busy host drops
//! decisions (docs/BENCHMARKS.md, "Peer mesh or routers", measures it).
//!
//! Every link refuses a message larger than [`RX_MAX_MESSAGE_BYTES`], twice our largest
//! (a full detection frame is about 135 kB; the codec refuses anything above
//! `spwi_proto::MAX_MESSAGE_BYTES`). Zenoh's own limit is 1 GiB, and it reassembles a
//! fragmented message before anyone can look at it, so one huge message would cost
//! hundreds of megabytes before the codec could refuse it (docs/FAULTS.md).
//!
//! A file given by the user is taken as is; set `transport/link/tx/lease` and the
//! queue size in it. Only the receive limit is lowered there too when the file leaves
//! it at Zenoh's default.

use anyhow::{anyhow, bail, Result};
use std::path::Path;

/// Link lease every spwi process uses unless its Zenoh file says otherwise (ms).
pub const LEASE_MS: u64 = 1000;
/// Keep-alive messages per lease period.
pub const KEEP_ALIVE: u64 = 4;
/// Batches in each link's queue for data-priority messages (Zenoh allows 1–16).
pub const DATA_QUEUE_BATCHES: u64 = 8;

/// Batches in each of a router's link queues for data-priority messages (Zenoh's most).
pub const ROUTER_DATA_QUEUE_BATCHES: u64 = 16;
/// How long a router's droppable message waits for a free batch (µs; Zenoh's: 1000).
/// Well within the tick's 60 ms decision deadline.
pub const ROUTER_WAIT_BEFORE_DROP_US: u64 = 10_000;

/// The largest message a link reassembles (bytes): twice the largest message spwi
/// decodes.
pub const RX_MAX_MESSAGE_BYTES: usize = 2 * spwi_proto::MAX_MESSAGE_BYTES;
/// Zenoh's own default for it.
const ZENOH_RX_MAX_MESSAGE_BYTES: usize = 1 << 30;

/// Builds the Zenoh config from an optional json5 file and `KEY:VALUE` overrides
/// (VALUE is json5, e.g. `mode:"peer"` or `listen/endpoints:["tcp/0.0.0.0:7447"]`).
pub fn build(file: Option<&Path>, overrides: &[String]) -> Result<zenoh::Config> {
    let mut c = from_file_or_defaults(file)?;
    apply(&mut c, overrides)?;
    Ok(c)
}

/// [`build`] for `spwi-router`: without a file, its links also get the deeper queues.
pub fn build_router(file: Option<&Path>, overrides: &[String]) -> Result<zenoh::Config> {
    let mut c = from_file_or_defaults(file)?;
    if file.is_none() {
        set(&mut c, "transport/link/tx/queue/size/data", &ROUTER_DATA_QUEUE_BATCHES.to_string())?;
        set(
            &mut c,
            "transport/link/tx/queue/congestion_control/drop/wait_before_drop",
            &ROUTER_WAIT_BEFORE_DROP_US.to_string(),
        )?;
    }
    apply(&mut c, overrides)?;
    Ok(c)
}

fn from_file_or_defaults(file: Option<&Path>) -> Result<zenoh::Config> {
    let mut c = file_or_defaults(file)?;
    let rx_key = "transport/link/rx/max_message_size";
    if c.get_json(rx_key).ok().and_then(|v| v.parse::<usize>().ok()) == Some(ZENOH_RX_MAX_MESSAGE_BYTES) {
        set(&mut c, rx_key, &RX_MAX_MESSAGE_BYTES.to_string())?;
    }
    Ok(c)
}

fn file_or_defaults(file: Option<&Path>) -> Result<zenoh::Config> {
    Ok(match file {
        Some(p) => zenoh::Config::from_file(p).map_err(|e| anyhow!("zenoh config {}: {e}", p.display()))?,
        None => {
            let mut c = zenoh::Config::default();
            set(&mut c, "transport/link/tx/lease", &LEASE_MS.to_string())?;
            set(&mut c, "transport/link/tx/keep_alive", &KEEP_ALIVE.to_string())?;
            set(&mut c, "transport/link/tx/queue/size/data", &DATA_QUEUE_BATCHES.to_string())?;
            c
        }
    })
}

fn apply(c: &mut zenoh::Config, overrides: &[String]) -> Result<()> {
    for o in overrides {
        let Some((key, value)) = o.split_once(':') else {
            bail!("--cfg {o:?}: expected KEY:VALUE, e.g. mode:\"peer\"");
        };
        set(c, key, value)?;
    }
    Ok(())
}

fn set(c: &mut zenoh::Config, key: &str, value: &str) -> Result<()> {
    c.insert_json5(key, value).map_err(|e| anyhow!("zenoh setting {key} = {value}: {e}"))
}

/// A peer on loopback for tests and the in-process demo: listens on an ephemeral
/// port, connects to `connect`, no multicast scouting.
pub fn loopback_peer(connect: &[String]) -> Result<zenoh::Config> {
    let mut c = build(None, &[])?;
    set(&mut c, "mode", r#""peer""#)?;
    set(&mut c, "listen/endpoints", r#"["tcp/127.0.0.1:0"]"#)?;
    set(&mut c, "connect/endpoints", &serde_json::to_string(connect)?)?;
    set(&mut c, "scouting/multicast/enabled", "false")?;
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_router_gets_deeper_queues_unless_its_file_or_an_override_says_otherwise() {
        let c = build_router(None, &[]).unwrap();
        assert_eq!(c.get_json("transport/link/tx/lease").unwrap(), "1000");
        assert_eq!(c.get_json("transport/link/tx/queue/size/data").unwrap(), "16");
        let wait = c.get_json("transport/link/tx/queue/congestion_control/drop/wait_before_drop").unwrap();
        assert_eq!(wait, "10000");
        let c = build_router(None, &["transport/link/tx/queue/size/data:4".to_owned()]).unwrap();
        assert_eq!(c.get_json("transport/link/tx/queue/size/data").unwrap(), "4");
        let file = std::env::temp_dir().join(format!("spwi-router-{}.json5", std::process::id()));
        std::fs::write(&file, "{ mode: \"router\" }").unwrap();
        let c = build_router(Some(&file), &[]).unwrap();
        std::fs::remove_file(&file).unwrap();
        assert_eq!(c.get_json("transport/link/tx/queue/size/data").unwrap(), "2", "a user's file is taken as is");
    }

    #[test]
    fn defaults_carry_the_short_lease_and_overrides_apply() {
        let c = build(None, &["mode:\"client\"".to_owned()]).unwrap();
        let lease = c.get_json("transport/link/tx/lease").unwrap();
        assert_eq!(lease, "1000");
        let rx = c.get_json("transport/link/rx/max_message_size").unwrap();
        assert_eq!(rx, RX_MAX_MESSAGE_BYTES.to_string(), "a link refuses what no spwi message needs");
        assert_eq!(c.get_json("transport/link/tx/queue/size/data").unwrap(), "8");
        assert_eq!(c.get_json("mode").unwrap(), "\"client\"");
    }

    #[test]
    fn malformed_overrides_are_refused_with_the_key() {
        assert!(build(None, &["no-colon".to_owned()]).unwrap_err().to_string().contains("KEY:VALUE"));
        let e = build(None, &["transport/link/tx/lease:\"soon\"".to_owned()]).unwrap_err().to_string();
        assert!(e.contains("transport/link/tx/lease"), "{e}");
    }
}
