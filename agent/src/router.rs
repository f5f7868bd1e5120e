//! `spwi-router`: a Zenoh router for hosts that cannot scout each other by multicast
//! (containers on a Docker network, robots on networks that drop multicast).
//!
//! Every daemon connects to it and learns the others' addresses from its gossip, then
//! talks to them directly (peer mode): the router is only a meeting point. If it goes
//! down, the robots already connected keep their links and keep deciding; robots that
//! start while it is down find no one until it is back. It is Zenoh's own router mode
//! (what `zenohd` runs, without plugins), so no extra program has to be installed.
//! In a secured fleet it takes a newer signed roster while it runs, as every member
//! does ([`crate::fleet::live`]), and reopens with its access rules: the robots' links
//! to it drop for a moment and come back (they talk to each other directly meanwhile).

use crate::cli::{init_tracing, spawn_signal_handler};
use crate::config::LogFormat;
use crate::fleet::live::{self, Watch};
use crate::fleet::Role;
use anyhow::{anyhow, Result};
use clap::Parser;
use std::path::PathBuf;
use std::process::ExitCode;
use tokio::sync::watch;

/// A Zenoh router for spwi fleets whose hosts cannot scout each other by multicast.
#[derive(Debug, Parser)]
#[command(name = "spwi-router", version)]
pub struct Args {
    /// Where to listen (Zenoh endpoint).
    #[arg(long, default_value = "tcp/0.0.0.0:7447")]
    pub listen: String,
    /// Zenoh's own config file (json5), as zenohd takes it.
    #[arg(long, env = "ZENOH_CONFIG")]
    pub zenoh_config: Option<PathBuf>,
    /// Zenoh setting override KEY:VALUE (VALUE in json5), repeatable.
    #[arg(long = "cfg", value_name = "KEY:VALUE")]
    pub cfg: Vec<String>,
    /// The fleet directory: accept only the fleet's members (mutual TLS, the roster's
    /// access rules on everything it forwards). A `tcp/` --listen becomes `tls/`.
    #[arg(long, env = "SPWI_FLEET_DIR")]
    pub fleet_dir: Option<PathBuf>,
    /// Whose certificate to present from --fleet-dir (a member of role router).
    #[arg(long, env = "SPWI_IDENTITY", default_value = "router", requires = "fleet_dir")]
    pub identity: String,
}

async fn run(args: Args) -> Result<()> {
    let mut overrides =
        vec![r#"mode:"router""#.to_owned(), format!("listen/endpoints:{}", serde_json::to_string(&[&args.listen])?)];
    overrides.extend(args.cfg);
    let mut config = crate::zenoh_config::build_router(args.zenoh_config.as_deref(), &overrides)?;
    let credentials = crate::fleet::secure_or_warn(
        &mut config,
        args.fleet_dir.as_deref(),
        &args.identity,
        Role::Router,
        "spwi-router",
    )?;
    let mut roster = credentials.map(Watch::new);
    let (tx, mut rx) = watch::channel(false);
    spawn_signal_handler(tx);
    loop {
        let session = zenoh::open(config.clone()).await.map_err(|e| anyhow!("cannot start the Zenoh router: {e}"))?;
        if let Some(w) = roster.as_mut() {
            w.listen(&session).await?;
        }
        tracing::info!(listen = %args.listen, zid = %session.zid(), "router up");
        let adopted = tokio::select! {
            _ = rx.wait_for(|stop| *stop) => None,
            adopted = live::adopted(roster.as_mut(), &session) => Some(adopted),
        };
        if let Some(Ok(a)) = &adopted {
            tokio::time::sleep(live::reopen_delay(&a.credentials.identity.name)).await;
            crate::fleet::secure::apply(&mut config, &a.credentials)?;
            live::for_reopening(&mut config)?;
        }
        session.close().await.map_err(|e| anyhow!("closing the router session: {e}"))?;
        match adopted {
            None => break,
            Some(Err(e)) => return Err(e),
            Some(Ok(_)) => tracing::info!("reopening with the new roster's access rules"),
        }
    }
    tracing::info!("router stopped");
    Ok(())
}

/// `main` of `spwi-router`.
pub fn main() -> ExitCode {
    let args = Args::parse();
    init_tracing(LogFormat::Human);
    crate::cli::run_main("spwi-router", run(args))
}
