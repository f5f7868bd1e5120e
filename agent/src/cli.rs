//! The `spwi-agent` command line: parse, start tracing, load config and models, run
//! the daemon until Ctrl-C / SIGTERM. The first signal leaves the fleet gracefully
//! (token undeclared, session closed); a second exits at once.

use crate::config::{AgentConfig, LogFormat};
use crate::daemon::{self, Options};
use crate::fleet::Role;
use anyhow::{Context, Result};
use clap::Parser;
use spwi_proto::{FleetId, RobotId};
use std::path::PathBuf;
use std::process::ExitCode;
use tokio::sync::watch;

/// One robot's spwi daemon: shares what it sees and agrees with its peers on where
/// the worker is going.
#[derive(Debug, Parser)]
#[command(name = "spwi-agent", version, subcommand_negates_reqs = true, args_conflicts_with_subcommands = true)]
pub struct Args {
    #[command(subcommand)]
    pub command: Option<Command>,
    /// This robot's id ([A-Za-z0-9_-]{1,64}); unique within the fleet.
    #[arg(long, env = "SPWI_ROBOT_ID", required_unless_present_any = ["replay", "robot_id_from_hostname", "probe"])]
    pub robot_id: Option<RobotId>,
    /// Use this host's name as the robot id (one daemon per host, e.g. a container
    /// replica); refused if the name is not a valid id.
    #[arg(long, env = "SPWI_ROBOT_ID_FROM_HOSTNAME", conflicts_with = "robot_id")]
    pub robot_id_from_hostname: bool,
    /// The fleet (team) to join: `default` unless given, or the one of --fleet-dir.
    #[arg(long, env = "SPWI_FLEET")]
    pub fleet: Option<FleetId>,
    /// The fleet directory (`spwi-agent fleet init`): join with mutual TLS and the
    /// roster's access rules. Without it the fleet is open to anyone on the network.
    #[arg(long, env = "SPWI_FLEET_DIR")]
    pub fleet_dir: Option<PathBuf>,
    /// Whose certificate to present from --fleet-dir (default: the robot id).
    #[arg(long, env = "SPWI_IDENTITY", requires = "fleet_dir")]
    pub identity: Option<String>,
    /// Agent settings (TOML); defaults apply to anything not set.
    #[arg(long, env = "SPWI_CONFIG")]
    pub config: Option<PathBuf>,
    /// Zenoh's own config file (json5), as zenohd takes it.
    #[arg(long, env = "ZENOH_CONFIG")]
    pub zenoh_config: Option<PathBuf>,
    /// Zenoh setting override KEY:VALUE (VALUE in json5), repeatable,
    /// e.g. --cfg 'connect/endpoints:["tcp/10.0.0.2:7447"]'.
    #[arg(long = "cfg", value_name = "KEY:VALUE")]
    pub cfg: Vec<String>,
    /// Serve /healthz, /status and /metrics on this address (overrides http.listen).
    #[arg(long)]
    pub http: Option<std::net::SocketAddr>,
    /// Model set folder (overrides models.dir).
    #[arg(long)]
    pub models: Option<PathBuf>,
    /// The factory's floor plan: where its stations stand (overrides floor.plan;
    /// `spwi-sim layout --plan` writes one from a layout).
    #[arg(long, value_name = "FILE", env = "SPWI_FLOOR_PLAN")]
    pub floor_plan: Option<PathBuf>,
    /// Record every input and output of the decision engine to this MCAP file.
    #[arg(long, value_name = "FILE")]
    pub record: Option<PathBuf>,
    /// Do not join a fleet: replay a recording through the same models and check that
    /// every output is what was recorded, bit for bit.
    #[arg(long, value_name = "FILE", conflicts_with = "record")]
    pub replay: Option<PathBuf>,
    /// Only ask the daemon serving HTTP on ADDR whether it is healthy (GET /healthz):
    /// exit 0 if it answers 200 within 2 s, 1 otherwise. For container health checks;
    /// every other option is ignored.
    #[arg(long, value_name = "ADDR")]
    pub probe: Option<std::net::SocketAddr>,
}

/// Commands other than running the daemon.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Manage a fleet's certificates and roster (who may join).
    #[command(subcommand)]
    Fleet(crate::fleet::cli::FleetCommand),
}

/// This host's name, as the kernel has it.
fn hostname() -> Result<String> {
    let name = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::env::var("HOSTNAME"))
        .context("cannot read this host's name (/proc/sys/kernel/hostname or $HOSTNAME)")?;
    Ok(name.trim().to_owned())
}

/// GET /healthz on `addr`; true on a 200 answer within 2 s.
pub fn probe(addr: std::net::SocketAddr) -> bool {
    use std::io::{Read, Write};
    let timeout = std::time::Duration::from_secs(2);
    let Ok(mut s) = std::net::TcpStream::connect_timeout(&addr, timeout) else { return false };
    let _ = s.set_read_timeout(Some(timeout));
    let _ = s.set_write_timeout(Some(timeout));
    if s.write_all(b"GET /healthz HTTP/1.1\r\nHost: spwi\r\nConnection: close\r\n\r\n").is_err() {
        return false;
    }
    let mut head = [0u8; 12];
    s.read_exact(&mut head).is_ok() && head.starts_with(b"HTTP/1.") && &head[9..12] == b"200"
}

/// Sets up `tracing`: `RUST_LOG` wins; otherwise info for spwi and only warnings and
/// errors from Zenoh, whose routine churn messages look alarming. Zenoh's TLS setup
/// warns on every link that it skips host-name checks, which a secured fleet does on
/// purpose (identity is the certificate's name, checked by the access rules).
pub fn init_tracing(format: LogFormat) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        tracing_subscriber::EnvFilter::new("info,zenoh=warn,zenoh_transport=error,zenoh_link_tls::utils=error")
    });
    // Colours only for a terminal: a log file, journald or `docker logs` gets plain text.
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let builder = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_ansi(ansi);
    let _ = match format {
        LogFormat::Human => builder.try_init(),
        LogFormat::Json => builder.json().try_init(),
    };
}

/// Resolves Ctrl-C / SIGTERM into the shutdown signal; a second one exits at once.
pub fn spawn_signal_handler(tx: watch::Sender<bool>) {
    tokio::spawn(async move {
        let mut signals = 0;
        loop {
            wait_for_signal().await;
            signals += 1;
            if signals == 1 {
                tracing::info!("shutting down (signal again to exit at once)");
                let _ = tx.send(true);
            } else {
                std::process::exit(130);
            }
        }
    });
}

async fn wait_for_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = tokio::signal::ctrl_c() => {}
                    _ = term.recv() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}

async fn run(args: Args) -> Result<()> {
    let mut config = AgentConfig::load(args.config.as_deref())?;
    if let Some(h) = args.http {
        config.http.listen = Some(h);
    }
    if let Some(m) = args.models {
        config.models.dir = Some(m);
    }
    if let Some(p) = args.floor_plan {
        config.floor.plan = Some(p);
    }
    init_tracing(config.log.format);
    config.validate()?;
    if let Some(file) = args.replay {
        return replay(&file, &config);
    }
    let robot = match args.robot_id {
        Some(id) => id,
        None if args.robot_id_from_hostname => {
            let name = hostname()?;
            RobotId::new(name.clone()).map_err(|e| anyhow::anyhow!("host name {name:?} cannot be a robot id: {e}"))?
        }
        None => anyhow::bail!("--robot-id is required"),
    };
    let mut zenoh = crate::zenoh_config::build(args.zenoh_config.as_deref(), &args.cfg)?;
    let identity = args.identity.unwrap_or_else(|| robot.to_string());
    let credentials =
        crate::fleet::secure_or_warn(&mut zenoh, args.fleet_dir.as_deref(), &identity, Role::Robot, "spwi-agent")?;
    if credentials.is_some() && identity != robot.as_str() {
        tracing::warn!(%robot, identity, "presenting another robot's certificate: every peer will refuse this robot's messages");
    }
    let fleet = crate::fleet::fleet_id(args.fleet, credentials.as_deref())?;
    let models = tokio::task::spawn_blocking({
        let config = config.clone();
        move || daemon::load_models(&config)
    })
    .await
    .context("model loading panicked")??;
    let (tx, rx) = watch::channel(false);
    spawn_signal_handler(tx);
    // The heap is the process's: one trimmer beside the daemon, stopped when it ends.
    let trim = tokio::spawn(daemon::memory::trim_every(daemon::memory::TRIM_PERIOD));
    let ran =
        daemon::run(Options { robot, fleet, config, zenoh, record: args.record, credentials }, models, rx, None).await;
    trim.abort();
    ran
}

fn replay(file: &std::path::Path, config: &AgentConfig) -> Result<()> {
    let recording = crate::record::read(file)?;
    let models = daemon::load_models(config)?;
    let replayed = crate::record::replay(&recording, &models)?;
    let decisions = replayed.outputs.iter().filter(|o| matches!(o, spwi_core::engine::Output::Decision(_))).count();
    first_difference("output", &replayed.outputs, &recording.outputs)?;
    first_difference("peer state (trust, frozen feeds)", &replayed.states, &recording.states)?;
    println!(
        "replayed {} inputs of robot {}: {} outputs, {decisions} decisions and their peer states, identical to the recording",
        recording.inputs.len(),
        recording.config.engine.robot,
        replayed.outputs.len()
    );
    Ok(())
}

/// An error naming the first `what` in which a replay differs from the recording.
fn first_difference<T: PartialEq>(what: &str, replayed: &[T], recorded: &[T]) -> Result<()> {
    if replayed == recorded {
        return Ok(());
    }
    let at = replayed.iter().zip(recorded).position(|(a, b)| a != b).unwrap_or(replayed.len().min(recorded.len()));
    anyhow::bail!(
        "replay differs from the recording at {what} {at} ({} replayed, {} recorded)",
        replayed.len(),
        recorded.len()
    )
}

/// Zenoh's transport tasks (rx, tx, accept, net), which by default run on runtimes of
/// their own (five threads), moved onto its one-thread app runtime: an agent's traffic is
/// a few messages per peer per tick, and waking a thread per message cost more than the
/// messages (docs/BENCHMARKS.md, "Zenoh's runtimes"). Only the agent's: the router,
/// which carries every robot's traffic, keeps Zenoh's own. `ZENOH_RUNTIME` in the
/// environment replaces it.
pub const ZENOH_RUNTIME_OF_AN_AGENT: &str =
    "(rx: (handover: app), tx: (handover: app), acc: (handover: app), net: (handover: app))";

/// The variable Zenoh reads its runtimes from (zenoh-runtime's `ZENOH_RUNTIME_ENV`).
const ZENOH_RUNTIME_ENV: &str = "ZENOH_RUNTIME";

/// `main` of `spwi-agent`.
pub fn main() -> ExitCode {
    if std::env::var_os(ZENOH_RUNTIME_ENV).is_none() {
        // Before any thread exists, and before Zenoh first reads it.
        std::env::set_var(ZENOH_RUNTIME_ENV, ZENOH_RUNTIME_OF_AN_AGENT);
    }
    let mut args = Args::parse();
    if let Some(Command::Fleet(cmd)) = args.command.take() {
        init_tracing(LogFormat::Human);
        return run_main("spwi-agent fleet", crate::fleet::cli::run(cmd));
    }
    if let Some(addr) = args.probe {
        return if probe(addr) { ExitCode::SUCCESS } else { ExitCode::FAILURE };
    }
    run_main("spwi-agent", run(args))
}

/// Runs a program's async part on a multi-threaded runtime; an error is printed as
/// `<program>: error: …` and gives a failing exit code.
pub fn run_main(program: &str, fut: impl std::future::Future<Output = Result<()>>) -> ExitCode {
    let rt = match tokio::runtime::Builder::new_multi_thread().enable_all().build() {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("{program}: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    match rt.block_on(fut) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{program}: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
