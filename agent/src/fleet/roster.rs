//! The roster (`fleet.toml`): who belongs to the fleet, in which role, with which public
//! key, and who has been revoked. It holds nothing secret; every host gets a copy, and
//! the access-control rules every process enforces are generated from it.

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
}

impl Role {
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Robot => "robot",
            Role::World => "world",
            Role::Router => "router",
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
    #[serde(default, rename = "member")]
    pub members: Vec<Member>,
}

impl Roster {
    pub fn new(fleet: FleetId) -> Roster {
        Roster { fleet, members: Vec::new() }
    }

    /// Reads and checks `fleet.toml`; every error names the file.
    pub fn load(path: &Path) -> Result<Roster> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("cannot read the roster {}", path.display()))?;
        let roster: Roster =
            toml::from_str(&text).with_context(|| format!("roster {} is malformed", path.display()))?;
        roster.check().with_context(|| format!("roster {}", path.display()))?;
        Ok(roster)
    }

    /// Writes `fleet.toml` (through a temporary file, so a crash leaves the old one).
    pub fn save(&self, path: &Path) -> Result<()> {
        let tmp = path.with_extension("toml.tmp");
        let text = format!(
            "# spwi fleet roster: written by `spwi-agent fleet`, public, copied to every host.\n{}",
            toml::to_string(self)?
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

pub(crate) fn encode_key(key: &[u8]) -> String {
    key.iter().map(|b| format!("{b:02x}")).collect()
}

fn decode_key(hex: &str) -> Option<[u8; 32]> {
    if hex.len() != 64 || !hex.is_ascii() {
        return None;
    }
    let mut out = [0u8; 32];
    for (i, byte) in out.iter_mut().enumerate() {
        *byte = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok()?;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn member(name: &str) -> Member {
        Member {
            name: RobotId::new(name).unwrap(),
            role: Role::Robot,
            public_key: encode_key(&[7; 32]),
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
