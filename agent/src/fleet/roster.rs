//! The roster (`fleet.toml`): who belongs to the fleet, in which role, with which public
//! key, and who has been revoked. It holds nothing secret; every host gets a copy, and
//! the access-control rules every process enforces are generated from it.
//!
//! It is signed: every change the operator's commands make raises its `version` and
//! signs it anew with the fleet CA's key ([`Roster::signed_bytes`]), and a process
//! takes it only if the signature verifies against `ca.crt`
//! ([`super::credentials::load_roster`]), so a host's copy edited by hand (a member's key
//! swapped, a revocation undone) is refused, naming the file.

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use spwi_proto::{FleetId, RobotId};
use std::path::Path;

/// What a member may publish.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// Publishes under `spwi/<fleet>/robot/<its name>/**` and holds `alive/<its name>`.
    Robot,
    /// The world or detector service: publishes every robot's detections and the truth.
    World,
    /// A Zenoh router: relays anything of the fleet, so it is trusted to enforce the
    /// rules on what it relays (it runs the same ones).
    Router,
    /// A dashboard, planner or logger: may follow everything of the fleet, and publish
    /// nothing, hold no liveliness token, vote never.
    Observer,
}

impl Role {
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Robot => "robot",
            Role::World => "world",
            Role::Router => "router",
            Role::Observer => "observer",
        }
    }
}

/// One admitted identity. Its name is its certificate's common name; names follow the
/// robot-id rules (`[A-Za-z0-9_-]{1,64}`) and are unique across roles.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Member {
    pub name: RobotId,
    pub role: Role,
    /// The member's Ed25519 public key, hex: it signs the ballots peers relay for it.
    pub public_key: String,
    /// When its certificate expires (RFC 3339), for operators.
    pub not_after: String,
    /// A revoked member is denied everything by every process that has this roster.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub revoked: bool,
}

impl Member {
    /// The public key as bytes (checked at load: 32 bytes of hex).
    pub fn public_key_bytes(&self) -> [u8; 32] {
        decode_key(&self.public_key).expect("checked when the roster was loaded")
    }
}

/// The whole roster.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Roster {
    pub fleet: FleetId,
    /// Raised by every change: a process holding a newer roster refuses an older one.
    #[serde(default)]
    pub version: u64,
    /// The fleet CA's Ed25519 signature over [`Roster::signed_bytes`], hex.
    #[serde(default)]
    pub signature: String,
    #[serde(default, rename = "member")]
    pub members: Vec<Member>,
}

impl Roster {
    pub fn new(fleet: FleetId) -> Roster {
        Roster { fleet, version: 0, signature: String::new(), members: Vec::new() }
    }

    /// What the CA signs: a label, then the roster as TOML without its signature.
    pub fn signed_bytes(&self) -> Vec<u8> {
        let unsigned = Roster { signature: String::new(), ..self.clone() };
        let mut bytes = b"spwi fleet roster\xff".to_vec();
        bytes.extend(toml::to_string(&unsigned).expect("a roster serialises").into_bytes());
        bytes
    }

    /// The next version, signed by `sign` (the CA's key).
    pub fn sign_next(&mut self, sign: impl FnOnce(&[u8]) -> Vec<u8>) {
        self.version += 1;
        self.signature = encode_hex(&sign(&self.signed_bytes()));
    }

    /// Whether the signature is the CA's whose raw Ed25519 public key is `ca_key`.
    pub fn signed_by(&self, ca_key: &[u8]) -> bool {
        let Some(signature) = decode_hex(&self.signature) else { return false };
        ring::signature::UnparsedPublicKey::new(&ring::signature::ED25519, ca_key)
            .verify(&self.signed_bytes(), &signature)
            .is_ok()
    }

    /// Reads and checks `fleet.toml`; every error names the file.
    pub fn load(path: &Path) -> Result<Roster> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("cannot read the roster {}", path.display()))?;
        Roster::parse(&text).with_context(|| format!("roster {}", path.display()))
    }

    /// Parses and checks a roster's TOML text (a file's, or one said on the fleet).
    pub fn parse(text: &str) -> Result<Roster> {
        let roster: Roster = toml::from_str(text).context("malformed")?;
        roster.check()?;
        Ok(roster)
    }

    /// The roster as TOML, as a member says it on the fleet (`super::live`).
    pub fn said(&self) -> Vec<u8> {
        toml::to_string(self).expect("a roster serialises").into_bytes()
    }

    /// Writes `fleet.toml` (through a temporary file, so a crash leaves the old one).
    pub fn save(&self, path: &Path) -> Result<()> {
        let tmp = path.with_extension("toml.tmp");
        let text = format!(
            "# spwi fleet roster: written by `spwi-agent fleet`, public, copied to every host.\n{}",
            String::from_utf8(self.said())?
        );
        std::fs::write(&tmp, text).with_context(|| format!("cannot write {}", tmp.display()))?;
        std::fs::rename(&tmp, path).with_context(|| format!("cannot replace {}", path.display()))
    }

    fn check(&self) -> Result<()> {
        for (i, m) in self.members.iter().enumerate() {
            if self.members[..i].iter().any(|o| o.name == m.name) {
                bail!("member {} is listed twice", m.name);
            }
            if decode_key(&m.public_key).is_none() {
                bail!("member {}: public_key is not 64 hex digits (an Ed25519 key)", m.name);
            }
        }
        Ok(())
    }

    pub fn get(&self, name: &str) -> Option<&Member> {
        self.members.iter().find(|m| m.name.as_str() == name)
    }

    /// Members not revoked.
    pub fn admitted(&self) -> impl Iterator<Item = &Member> {
        self.members.iter().filter(|m| !m.revoked)
    }
}

pub(crate) fn encode_hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn decode_key(hex: &str) -> Option<[u8; 32]> {
    if hex.len() != 64 {
        return None;
    }
    decode_hex(hex)?.try_into().ok()
}

fn decode_hex(hex: &str) -> Option<Vec<u8>> {
    if !hex.len().is_multiple_of(2) || !hex.is_ascii() {
        return None;
    }
    (0..hex.len() / 2).map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn member(name: &str) -> Member {
        Member {
            name: RobotId::new(name).unwrap(),
            role: Role::Robot,
            public_key: encode_hex(&[7; 32]),
            not_after: "2027-01-01T00:00:00Z".into(),
            revoked: false,
        }
    }

    #[test]
    fn a_roster_round_trips_through_its_file() {
        let dir = std::env::temp_dir().join(format!("spwi-roster-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut r = Roster::new(FleetId::new("f").unwrap());
        r.members.push(member("r1"));
        r.members.push(Member { revoked: true, ..member("r2") });
        let path = dir.join("fleet.toml");
        r.save(&path).unwrap();
        assert_eq!(Roster::load(&path).unwrap(), r);
        assert_eq!(r.admitted().count(), 1);
        assert_eq!(r.get("r1").unwrap().public_key_bytes(), [7; 32]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_bad_roster_is_refused_naming_the_member() {
        let mut r = Roster::new(FleetId::new("f").unwrap());
        r.members.push(member("r1"));
        r.members.push(member("r1"));
        assert!(r.check().unwrap_err().to_string().contains("r1 is listed twice"));
        r.members[1] = Member { public_key: "zz".into(), ..member("r2") };
        assert!(r.check().unwrap_err().to_string().contains("r2: public_key"));
        let e = toml::from_str::<Roster>("fleet = \"f\"\n[[member]]\nname = \"bad name\"\n").unwrap_err();
        assert!(e.to_string().contains("bad name"), "{e}");
    }
}
