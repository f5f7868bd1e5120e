//! Signed votes, so that a relayed ballot is worth its origin's word.
//!
//! Access control vouches for a message by the link it arrives on. A ballot relayed by
//! a peer arrives on the relayer's link, and the relayer could have changed it. So in a
//! secured fleet every robot signs its vote with its fleet key (Ed25519 is
//! deterministic: the copy it relays later carries the same signature), and a relayed
//! vote of another robot counts only if its origin's signature verifies against the
//! roster. The signature covers the fleet, the voter's instance (its run) and the tick
//! (a period of the fleet's clock), so a vote recorded elsewhere or earlier is refused:
//! by its signature in another fleet, by the engine's clock window after a restart, and
//! by the engine's check of the origin's live instance within the window. The relayer's own vote in its ballots needs none: its link vouches for it.
//! A vote already heard directly or already verified is recognised by its bytes and
//! not verified again, so each distinct vote costs at most one verification.
//!
//! A member that signs two different votes for one tick (equivocation: telling some
//! robots one thing and others another, so that their decisions and lessons part) is
//! caught as soon as both reach one robot: two valid signatures of one origin over two
//! votes of the same tick and instance are proof. The later copy is dropped and the
//! proof counted and logged with the member's name ([`Checked::equivocated`]).
//!
//! The engine stays unaware: the daemon signs what the engine outputs and filters what
//! it inputs, so recordings replay without keys.

use super::Credentials;
use spwi_core::engine::{Input, Output};
use spwi_proto::{FleetId, RobotId, VoteMsg};
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

/// Ticks of authentic votes remembered (10 s at 10 Hz; relays come within a tick).
const KEEP_TICKS: u64 = 100;

/// What [`SignedVotes::check`] dropped from an input.
#[derive(Debug, Default, PartialEq)]
pub struct Checked {
    /// Relayed votes without their origin's signature.
    pub forged: usize,
    /// Origins caught signing two different votes for one tick (one entry per proof).
    pub equivocated: Vec<RobotId>,
}

enum Authentic {
    Yes,
    Forged,
    /// Signed by its origin, but it signed another vote for the tick.
    Equivocation,
}

/// Signs this robot's votes and checks the relayed votes of others.
pub struct SignedVotes {
    creds: Arc<Credentials>,
    /// Signatures cover the fleet: a vote signed for one fleet counts in no other.
    fleet: FleetId,
    robot: RobotId,
    /// Votes known authentic, as signed bytes, by tick and origin.
    known: BTreeMap<u64, HashMap<RobotId, Vec<u8>>>,
    /// Our latest vote's signed bytes and signature: the vote goes out, then again in
    /// our relay of the tick, and is signed once.
    own: Option<(Vec<u8>, Vec<u8>)>,
}

impl SignedVotes {
    pub fn new(creds: Arc<Credentials>, fleet: FleetId, robot: RobotId) -> SignedVotes {
        SignedVotes { creds, fleet, robot, known: BTreeMap::new(), own: None }
    }

    /// Checks votes against a newer roster from now on: a newly admitted robot's
    /// signature counts, a revoked one's no longer does.
    pub fn set_credentials(&mut self, creds: Arc<Credentials>) {
        self.creds = creds;
    }

    /// Signs this robot's own votes in an output (its vote in its share of a tick, the
    /// same vote alone for observers, and its vote among the ballots it relays).
    pub fn sign(&mut self, out: &mut Output) {
        let own = match out {
            Output::Embedding(e) => e.vote.as_mut_slice(),
            Output::Vote(v) => std::slice::from_mut(v),
            Output::Ballots(b) => b.votes.as_mut_slice(),
            _ => return,
        };
        for v in own.iter_mut().filter(|v| v.robot == self.robot && v.signature.is_empty()) {
            let bytes = v.signed_bytes(&self.fleet);
            v.signature = match &self.own {
                Some((signed, signature)) if *signed == bytes => signature.clone(),
                _ => {
                    let signature = self.creds.sign(&bytes).to_vec();
                    self.own = Some((bytes, signature.clone()));
                    signature
                }
            };
        }
    }

    /// Remembers peers' votes heard directly; drops relayed votes whose origin's
    /// signature does not verify, and the copies that prove an equivocation. Our own
    /// vote, heard back or relayed back, is neither kept nor checked: the engine
    /// ignores it.
    pub fn check(&mut self, input: &mut Input) -> Checked {
        let mut checked = Checked::default();
        match input {
            Input::Embedding(e) if e.robot != self.robot => {
                if let Some(v) = &e.vote {
                    // Heard directly: the link vouches for it, and it wins over any
                    // relayed copy; one that differs from a copy its origin signed is
                    // proof all the same.
                    let bytes = v.signed_bytes(&self.fleet);
                    if self.known(v).is_some_and(|k| *k != bytes) {
                        checked.equivocated.push(v.robot.clone());
                    }
                    self.remember(v, bytes);
                }
            }
            // The relayer's own vote needs no signature (its link vouches for it), nor
            // ours, which the engine ignores.
            Input::Ballots(b) => {
                let vouched = [b.robot.clone(), self.robot.clone()];
                self.keep_authentic(&vouched, &mut b.votes, &mut checked);
            }
            // A history's votes are all past ones: each needs its origin's signature,
            // ours included; its sender's own the engine never takes.
            Input::History(h) => {
                let vouched = [h.robot.clone()];
                for lesson in &mut h.lessons {
                    self.keep_authentic(&vouched, &mut lesson.votes, &mut checked);
                }
            }
            _ => {}
        }
        checked
    }

    /// Drops from `votes` those of origins other than `vouched` whose signature does
    /// not verify or that prove an equivocation.
    fn keep_authentic(&mut self, vouched: &[RobotId], votes: &mut Vec<VoteMsg>, checked: &mut Checked) {
        votes.retain(|v| {
            if vouched.contains(&v.robot) {
                return true;
            }
            match self.authentic(v) {
                Authentic::Yes => true,
                Authentic::Forged => {
                    checked.forged += 1;
                    false
                }
                Authentic::Equivocation => {
                    checked.equivocated.push(v.robot.clone());
                    false
                }
            }
        });
    }

    /// The signed bytes of the vote of `v`'s origin and tick known authentic, if any.
    fn known(&self, v: &VoteMsg) -> Option<&Vec<u8>> {
        self.known.get(&v.tick).and_then(|m| m.get(&v.robot))
    }

    fn authentic(&mut self, v: &VoteMsg) -> Authentic {
        let bytes = v.signed_bytes(&self.fleet);
        let same_as_known = self.known(v).map(|k| *k == bytes);
        if same_as_known == Some(true) {
            return Authentic::Yes;
        }
        if !self.creds.verify(&v.robot, &bytes, &v.signature) {
            return Authentic::Forged;
        }
        if same_as_known == Some(false) {
            return Authentic::Equivocation; // the first stays: it is what we counted
        }
        self.remember(v, bytes);
        Authentic::Yes
    }

    fn remember(&mut self, v: &VoteMsg, bytes: Vec<u8>) {
        self.known.entry(v.tick).or_default().insert(v.robot.clone(), bytes);
        let newest = self.known.last_key_value().map_or(0, |(t, _)| *t);
        while self.known.first_key_value().is_some_and(|(t, _)| t + KEEP_TICKS < newest) {
            self.known.pop_first();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::authority::ThrowawayFleet;
    use super::super::Role;
    use super::*;
    use spwi_proto::{BallotsMsg, EmbeddingMsg, FleetId, Station, StepVote};

    fn id(s: &str) -> RobotId {
        RobotId::new(s).unwrap()
    }

    fn vote(robot: &str, tick: u64, confidence: f32) -> VoteMsg {
        VoteMsg {
            robot: id(robot),
            instance: 1,
            tick,
            steps: vec![StepVote { class: Station::Workstation, confidence }],
            visibility: 1,
            quality: 1.0,
            worker: None,
            signature: Vec::new(),
        }
    }

    #[test]
    fn a_relayed_vote_counts_only_with_its_origins_signature_and_two_signed_versions_prove_equivocation() {
        let members = [("a", Role::Robot), ("b", Role::Robot), ("c", Role::Robot)];
        let fleet = ThrowawayFleet::create("signed", &FleetId::new("f").unwrap(), &members).unwrap();
        let creds = |r: &str| Arc::new(Credentials::load(&fleet.dir, r).unwrap());
        let f = FleetId::new("f").unwrap();
        let signing = |r: &str| SignedVotes::new(creds(r), f.clone(), id(r));
        let (mut a, mut b) = (signing("a"), signing("b"));
        let c = || signing("c");
        let share = |v: VoteMsg| EmbeddingMsg {
            robot: v.robot.clone(),
            instance: v.instance,
            tick: v.tick,
            embedding: None,
            visibility: 1,
            vote: Some(v),
            worker: None,
            facing: None,
            landmarks: Vec::new(),
            verdict: None,
            people: Vec::new(),
        };
        let signed = |s: &mut SignedVotes, v: VoteMsg| {
            let mut out = Output::Embedding(share(v));
            s.sign(&mut out);
            let Output::Embedding(e) = out else { unreachable!() };
            e.vote.unwrap()
        };
        let from_a = signed(&mut a, vote("a", 5, 0.9));
        assert_eq!(from_a.signature.len(), 64);
        let mut again =
            Output::Ballots(BallotsMsg { robot: id("a"), instance: 1, tick: 5, votes: vec![vote("a", 5, 0.9)] });
        a.sign(&mut again);
        let Output::Ballots(relayed_by_a) = again else { unreachable!() };
        assert_eq!(relayed_by_a.votes[0], from_a, "the vote relayed is signed as the vote sent");
        let mut alone = Output::Vote(vote("a", 5, 0.9));
        a.sign(&mut alone);
        assert_eq!(alone, Output::Vote(from_a.clone()), "and so is the copy for observers");

        // b relays a's vote faithfully, a forged one, an unsigned one, and its own unsigned vote.
        let forged = VoteMsg { steps: vec![StepVote { class: Station::Assembly, confidence: 0.9 }], ..from_a.clone() };
        let ballots = |votes| Input::Ballots(BallotsMsg { robot: id("b"), instance: 1, tick: 5, votes });
        let mut input = ballots(vec![from_a.clone(), vote("b", 5, 0.5)]);
        assert_eq!(c().check(&mut input), Checked::default());
        for bad in [forged.clone(), vote("a", 5, 0.9), signed(&mut b, vote("a", 5, 0.9))] {
            let mut input = ballots(vec![bad, vote("b", 5, 0.5)]);
            assert_eq!(c().check(&mut input).forged, 1, "a vote of a not signed by a must not count");
            let Input::Ballots(kept) = input else { unreachable!() };
            assert_eq!(kept.votes, vec![vote("b", 5, 0.5)]);
        }
        // Once a's vote is known (heard directly), a copy of it needs no verification;
        // anything else still does.
        let mut c = c();
        assert_eq!(c.check(&mut Input::Embedding(share(from_a.clone()))), Checked::default());
        assert_eq!(c.check(&mut ballots(vec![vote("a", 5, 0.9)])), Checked::default(), "the very vote heard directly");
        assert_eq!(c.check(&mut ballots(vec![forged])).forged, 1);
        // a's vote signed for another fleet of the same CA counts in no other
        let elsewhere = SignedVotes::new(creds("c"), FleetId::new("g").unwrap(), id("c"));
        let mut elsewhere = elsewhere;
        assert_eq!(elsewhere.check(&mut ballots(vec![from_a.clone()])).forged, 1, "signed for fleet f, not g");

        // a signs a second, different vote for tick 5 and sends it to some robots: the
        // first robot that holds both has proof, whichever came first and however.
        let mut liar = signing("a");
        let other = signed(
            &mut liar,
            VoteMsg { steps: vec![StepVote { class: Station::Assembly, confidence: 0.9 }], ..vote("a", 5, 0.9) },
        );
        assert_eq!(other.signature.len(), 64);
        let mut c = signing("c");
        c.check(&mut Input::Embedding(share(from_a.clone())));
        let mut input = ballots(vec![other.clone(), vote("b", 5, 0.5)]);
        assert_eq!(c.check(&mut input), Checked { forged: 0, equivocated: vec![id("a")] });
        let Input::Ballots(kept) = input else { unreachable!() };
        assert_eq!(kept.votes, vec![vote("b", 5, 0.5)], "the second version is dropped, the first stays");
        let mut d = signing("c");
        assert_eq!(d.check(&mut ballots(vec![other])).equivocated, vec![], "one version alone proves nothing");
        let mut direct = Input::Embedding(share(from_a));
        assert_eq!(d.check(&mut direct).equivocated, vec![id("a")], "relayed first, then the other heard directly");
        let Input::Embedding(e) = direct else { unreachable!() };
        assert!(e.vote.is_some(), "a vote heard directly is the engine's to weigh");
    }
}
