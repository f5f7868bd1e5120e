//! Real packet loss between agent processes: each robot runs in a network namespace of
//! its own, on a bridge (see `spwi_tests::netns`), and iptables drops 10 % and then 30 %
//! of the packets a robot receives from the other robots. The fleet must keep deciding
//! every tick and agree; the figures are printed. Twice: on TCP links (an open fleet),
//! and on QUIC links of mixed reliability (a secured fleet; the per-tick messages go as
//! datagrams). Needs root (CI runs as root and sets SPWI_REQUIRE_NETNS=1, so there it
//! cannot skip); elsewhere it says loudly it skipped.
//! Run: `cargo test --workspace --test lossy_links -- --nocapture` to see the figures.
//! The TCP links run as deploy/README.md ("Lossy links") tells an operator of lossy TCP
//! links to set them up: the robots' routes resend a lost segment after 5 ms instead of
//! Linux's 200 ms (`rto_min`). `SPWI_TEST_RTO_MIN=200ms` measures Linux's own timeout
//! (figures printed; asserted only that every robot keeps deciding).

use spwi_agent::fleet::authority::ThrowawayFleet;
use spwi_proto::FleetId;
use spwi_tests::netns::{self, LossyNetwork};
use spwi_tests::*;
use std::time::{Duration, Instant};

const EXE: &str = env!("CARGO_BIN_EXE_spwi-test-agent");
const TICK: Duration = Duration::from_millis(100);
const ROBOTS: usize = 3;
/// A phase: packets dropped between robots, the least share of common ticks with one
/// decision, the least share of ticks each robot decides.
type Phase = (f64, f64, f64);
/// On TCP a lost segment holds every later message of its link until it is resent. With
/// the routes' `rto_min` at 5 ms, at 10 % one decision on 100 % of ticks in every run here
/// (seven, CI's among them). At 30 % on 35–73 % in six runs, and on 2 % in one of CI's:
/// head-of-line blocking on the links themselves, with retransmissions that back off
/// exponentially, leaves agreement to chance, so there only deciding is asserted (every
/// robot still decides); a fleet on links that lossy runs QUIC (the next test). The
/// fixture's random votes make this the harshest case: a missing ballot changes the
/// decision. Even with nothing dropped a vote can miss the 60 ms deadline on a loaded
/// two-core machine: 100 % in every run here, 98.0 % (two ticks of 99) in one of CI's;
/// so 95 % is asked there.
const TCP: [Phase; 3] = [(0.0, 0.95, 0.97), (0.10, 0.95, 0.95), (0.30, 0.0, 0.90)];
/// The minimum retransmission timeout the robots' routes get (deploy/README.md).
const RTO_MIN: &str = "5ms";
/// With any other minimum, Linux's own 200 ms say, a resent segment comes after the 60 ms
/// decision deadline: at 10 % one decision on 92–98 % of ticks in most runs here, but on
/// 55.6 % in one of CI's; so only deciding is asserted then.
const TCP_LINUX_RTO: [Phase; 3] = [(0.0, 0.95, 0.97), (0.10, 0.0, 0.95), (0.30, 0.0, 0.90)];
/// On QUIC with mixed reliability a lost datagram loses one message; the ballot relay
/// and the asks for a missing vote make up for it: at 10 % 100 % in every run, at 30 %
/// 80.8–100 % in nine of ten runs here (median 93.4; without asks 75.8–90.9 in five, and
/// 42.4 % in one of CI's). What they cannot make up for is a link that delivers nothing
/// for a few ticks (QUIC's congestion control under heavy loss holds datagrams back):
/// then a robot decides on its own vote alone, as in the tenth run (51.5 %). The bound at
/// 30 % leaves room for such a stall.
const QUIC: [Phase; 3] = [(0.0, 0.95, 0.97), (0.10, 0.95, 0.95), (0.30, 0.40, 0.90)];

/// True when this machine cannot drop packets between namespaces (said loudly; where
/// SPWI_REQUIRE_NETNS is set, a failure instead).
fn skipped() -> bool {
    let Some(why) = LossyNetwork::unavailable() else { return false };
    assert!(std::env::var_os("SPWI_REQUIRE_NETNS").is_none(), "SPWI_REQUIRE_NETNS is set but this {why}");
    eprintln!("!!!!!!!! SKIPPED: real packet loss between namespaces ({why}) !!!!!!!!");
    true
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn robots_keep_deciding_and_agreeing_when_their_tcp_links_drop_packets() {
    if skipped() {
        return;
    }
    let _serial = serial().await;
    within!(120, "test", async {
        let rto_min = std::env::var("SPWI_TEST_RTO_MIN").unwrap_or_else(|_| RTO_MIN.into());
        let phases = if rto_min == RTO_MIN { TCP } else { TCP_LINUX_RTO };
        eprintln!("tcp: the robots' routes resend a lost segment after {rto_min} at the earliest");
        let net = LossyNetwork::create(ROBOTS, Some(&rto_min)).unwrap();
        let hub = Hub::start_listening("lossy", &format!("tcp/{}:0", netns::HOST_ADDRESS)).await.unwrap();
        lose_packets(&net, &hub, "tcp", "", phases).await;
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn robots_keep_deciding_and_agreeing_when_their_quic_links_drop_packets() {
    if skipped() {
        return;
    }
    let _serial = serial().await;
    within!(120, "test", async {
        let net = LossyNetwork::create(ROBOTS, None).unwrap();
        let ids: Vec<_> = (0..ROBOTS).map(|i| id(&format!("n{i}"))).collect();
        let secured = ThrowawayFleet::with_world("lossyquic", &FleetId::new("lossyquic").unwrap(), &ids).unwrap();
        let endpoint = format!("quic/{}:0?mixed_rel=1", netns::HOST_ADDRESS);
        let hub = Hub::start_secured_listening(&secured.dir.root, "world", &endpoint).await.unwrap();
        lose_packets(&net, &hub, "quic", "?mixed_rel=1", QUIC).await;
    });
}

/// Runs the robots of `net` on `protocol` links (`metadata` appended to their
/// endpoints), drops packets between them phase by phase, and checks each phase's
/// decisions and agreement.
async fn lose_packets(net: &LossyNetwork, hub: &Hub, protocol: &str, metadata: &str, phases: [Phase; 3]) {
    let collector = hub.decisions().await.unwrap();
    let ids: Vec<_> = (0..ROBOTS).map(|i| id(&format!("n{i}"))).collect();
    let publisher = Publisher::start(hub, ids.clone(), TICK);
    let _agents: Vec<_> = ids
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let listen = format!("{protocol}/{}:7447{metadata}", net.address(i));
            agent_process_with(net.command(i, EXE), hub, r, &listen)
        })
        .collect();
    collector.wait_members(&ids, ROBOTS as u32, Instant::now(), Duration::from_secs(20)).await.unwrap();
    for (loss, least_agreement, least_decided) in phases {
        net.drop_between_robots(loss).unwrap();
        tokio::time::sleep(Duration::from_secs(2)).await;
        let from = publisher.current_tick();
        tokio::time::sleep(Duration::from_secs(10)).await;
        let to = publisher.current_tick() - 2; // the last ticks' decisions may be on their way
        let ticks = (to - from + 1) as f64;
        let (agreement, common) = collector.agreement(&ids, from, to);
        let by = collector.by_robot();
        let decided: Vec<f64> =
            ids.iter().map(|r| by.get(r).map_or(0, |m| m.range(from..=to).count()) as f64 / ticks).collect();
        // Robots that counted the same ballots (the same digest) decide the same: what
        // disagreement there is comes from votes lost on the way.
        let (mut same_ballots, mut same_ballots_differ) = (0, 0);
        for t in from..=to {
            let Some(ds) = ids.iter().map(|r| by.get(r)?.get(&t)).collect::<Option<Vec<_>>>() else { continue };
            if ds.iter().all(|d| d.digest == ds[0].digest) {
                same_ballots += 1;
                same_ballots_differ += usize::from(ds.iter().any(|d| d.steps != ds[0].steps));
            }
        }
        eprintln!(
            "{protocol}: {:.0} % of packets between robots dropped: one decision on {:.1} % of {common} common ticks; \
             each robot decided {:?} of {ticks} ticks; the same ballots counted on {:.1} %",
            loss * 100.0,
            agreement * 100.0,
            decided.iter().map(|d| format!("{:.1} %", d * 100.0)).collect::<Vec<_>>(),
            same_ballots as f64 / ticks * 100.0
        );
        for (r, d) in ids.iter().zip(&decided) {
            assert!(*d >= least_decided, "{r} decided {:.1} % of ticks at {loss} loss over {protocol}", d * 100.0);
        }
        assert_eq!(same_ballots_differ, 0, "robots that counted the same ballots decided differently at {loss} loss");
        assert!(
            agreement >= least_agreement,
            "one decision on {:.1} % of ticks at {loss} loss over {protocol}, at least {least_agreement} expected",
            agreement * 100.0
        );
    }
    net.drop_between_robots(0.0).unwrap();
}
