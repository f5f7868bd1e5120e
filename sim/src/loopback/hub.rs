//! The hub: the observer's own Zenoh session, listening on an ephemeral port, which
//! every agent of the fleet connects to. On a secured fleet it presents a member's
//! certificate (the world's: it publishes the detections). In a fleet of routers'
//! clients it is a client of a router too.

use super::Decisions;
use anyhow::{anyhow, Context, Result};
use spwi_agent::fleet::{secure, Credentials, FleetDir};
use spwi_agent::zenoh_config;
use spwi_proto::FleetId;
use std::path::{Path, PathBuf};
use std::sync::Arc;

pub struct Hub {
    pub session: zenoh::Session,
    /// What agents connect to: where it listens, or its router when it is a client.
    pub locator: String,
    pub fleet: FleetId,
    /// The fleet directory when the fleet is secured.
    pub fleet_dir: Option<PathBuf>,
}

impl Hub {
    /// An open hub of fleet `fleet` on loopback.
    pub async fn start(fleet: &str) -> Result<Hub> {
        Self::start_listening(fleet, "tcp/127.0.0.1:0").await
    }

    /// An open hub listening on `endpoint` (e.g. an address on a test network's bridge).
    pub async fn start_listening(fleet: &str, endpoint: &str) -> Result<Hub> {
        let mut config = zenoh_config::loopback_peer(&[])?;
        config.insert_json5("listen/endpoints", &serde_json::to_string(&[endpoint])?).map_err(|e| anyhow!(e))?;
        Self::open(config, FleetId::new(fleet)?, None).await
    }

    /// An open hub of fleet `fleet` as a Zenoh client of `routers` (the first it
    /// reaches; see `Routers::connect_from`).
    pub async fn start_client(fleet: &str, routers: &[String]) -> Result<Hub> {
        let locator = routers.first().context("a client hub needs a router")?.clone();
        let config = zenoh_config::build(
            None,
            &[
                r#"mode:"client""#.to_owned(),
                format!("connect/endpoints:{}", serde_json::to_string(routers)?),
                "scouting/multicast/enabled:false".to_owned(),
            ],
        )?;
        let session = zenoh::open(config).await.map_err(|e| anyhow!("the hub's zenoh session: {e}"))?;
        Ok(Hub { session, locator, fleet: FleetId::new(fleet)?, fleet_dir: None })
    }

    /// A hub of the secured fleet in `dir`, presenting the certificate of `identity`.
    pub async fn start_secured(dir: &Path, identity: &str) -> Result<Hub> {
        Self::start_secured_listening(dir, identity, "tls/127.0.0.1:0").await
    }

    /// The same, listening on `endpoint` (`tls/…` or `quic/…`).
    pub async fn start_secured_listening(dir: &Path, identity: &str, endpoint: &str) -> Result<Hub> {
        let (mut config, creds) = secured_peer(dir, identity, &[])?;
        config.insert_json5("listen/endpoints", &serde_json::to_string(&[endpoint])?).map_err(|e| anyhow!(e))?;
        Self::open(config, creds.roster.fleet.clone(), Some(dir.to_owned())).await
    }

    async fn open(config: zenoh::Config, fleet: FleetId, fleet_dir: Option<PathBuf>) -> Result<Hub> {
        let session = zenoh::open(config).await.map_err(|e| anyhow!("the hub's zenoh session: {e}"))?;
        let locator =
            session.info().locators().await.into_iter().next().context("the hub listens nowhere")?.to_string();
        Ok(Hub { session, locator, fleet, fleet_dir })
    }

    /// Collects, from now on, every decision the fleet's agents publish.
    pub async fn decisions(&self) -> Result<Decisions> {
        Decisions::subscribe(&self.session, &self.fleet).await
    }

    /// An open loopback peer connected to the hub.
    pub fn peer_config(&self) -> Result<zenoh::Config> {
        zenoh_config::loopback_peer(std::slice::from_ref(&self.locator))
    }

    /// The config and credentials of a member presenting `identity`: open when the
    /// hub is, else secured from the hub's fleet directory.
    pub fn member_config(&self, identity: &str) -> Result<(zenoh::Config, Option<Arc<Credentials>>)> {
        match &self.fleet_dir {
            None => Ok((self.peer_config()?, None)),
            Some(dir) => {
                let (c, creds) = secured_peer(dir, identity, std::slice::from_ref(&self.locator))?;
                Ok((c, Some(creds)))
            }
        }
    }
}

/// A loopback peer connected to `connect`, secured as `identity` of the fleet in `dir`.
pub fn secured_peer(dir: &Path, identity: &str, connect: &[String]) -> Result<(zenoh::Config, Arc<Credentials>)> {
    let creds = Credentials::load(&FleetDir::new(dir), identity)?;
    let mut c = zenoh_config::loopback_peer(connect)?;
    secure::apply(&mut c, &creds)?;
    Ok((c, Arc::new(creds)))
}
