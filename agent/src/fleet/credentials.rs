//! What a running process holds of the fleet directory: the roster, and its own
//! identity's certificate and key, every one checked before any connection is made.
//!
//! The checks are the ones TLS would make later, only with an error that names the
//! file: a member the roster does not admit, a certificate of another name, another CA,
//! out of its validity, or not matching the roster's key, a key that is not the
//! certificate's. An expired certificate is refused here with its date; a peer's
//! expired certificate is refused by the TLS handshake.

use super::roster::{Member, Roster};
use super::FleetDir;
use anyhow::{anyhow, bail, Context, Result};
use ring::signature::{Ed25519KeyPair, KeyPair as _, UnparsedPublicKey, ED25519};
use spwi_proto::RobotId;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use x509_parser::pem::Pem;

/// A member's credentials, checked.
pub struct Credentials {
    /// Where they were loaded from; a newer roster adopted at run time is written back
    /// to its `fleet.toml`.
    pub dir: FleetDir,
    pub roster: Roster,
    pub identity: Member,
    pub ca_cert: PathBuf,
    /// The CA's raw Ed25519 public key: every roster adopted later must verify against it.
    ca_key: Vec<u8>,
    pub cert: PathBuf,
    pub key: PathBuf,
    signer: Ed25519KeyPair,
    /// Public keys of the admitted robots, by name: only a robot's signature makes a
    /// relayed vote count.
    keys: HashMap<RobotId, [u8; 32]>,
}

impl std::fmt::Debug for Credentials {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // never the key
        f.debug_struct("Credentials").field("identity", &self.identity.name).field("cert", &self.cert).finish()
    }
}

impl Credentials {
    /// Loads and checks `identity`'s credentials from `dir`.
    pub fn load(dir: &FleetDir, identity: &str) -> Result<Credentials> {
        let (ca_cert, cert, key) = (dir.ca_cert(), dir.member_cert(identity), dir.member_key(identity));
        let ca_pem = read_pem(&ca_cert)?;
        let ca = parse(&ca_pem, &ca_cert)?;
        let roster = signed_roster(dir, &ca)?;
        let member = admitted(&roster, identity).map_err(|e| anyhow!("{e} in {}", dir.roster().display()))?;
        if !ca.is_ca() {
            bail!("{} is not a CA certificate", ca_cert.display());
        }
        let pem = read_pem(&cert)?;
        let x509 = parse(&pem, &cert)?;
        let cn = x509.subject().iter_common_name().next().and_then(|c| c.as_str().ok()).unwrap_or("");
        if cn != identity {
            bail!("{}: the certificate is for {cn:?}, not {identity:?}", cert.display());
        }
        x509.verify_signature(Some(ca.public_key()))
            .map_err(|_| anyhow!("{}: not signed by the fleet's CA {}", cert.display(), ca_cert.display()))?;
        let validity = x509.validity();
        let now = x509_parser::time::ASN1Time::now();
        if validity.not_after < now {
            bail!("{}: the certificate of {identity} expired on {}", cert.display(), validity.not_after);
        }
        if validity.not_before > now {
            bail!("{}: the certificate of {identity} is not valid before {}", cert.display(), validity.not_before);
        }
        let public = x509.public_key().subject_public_key.data.to_vec();
        if public != member.public_key_bytes() {
            bail!("{}: the certificate's key is not the one the roster lists for {identity}", cert.display());
        }
        let signer = load_key(&key)?;
        if signer.public_key().as_ref() != public.as_slice() {
            bail!("{}: this key does not belong to the certificate {}", key.display(), cert.display());
        }
        let keys = robot_keys(&roster);
        let ca_key = ca.public_key().subject_public_key.data.to_vec();
        Ok(Credentials { dir: dir.clone(), roster, identity: member, ca_cert, ca_key, cert, key, signer, keys })
    }

    /// These credentials under `roster`, a roster heard or read while running: taken
    /// only if the fleet's CA signed it, for this fleet, newer than the one held, and
    /// still admitting this identity with the same key. Every refusal says why.
    pub fn adopt(&self, roster: Roster) -> std::result::Result<Credentials, Refusal> {
        if roster.fleet != self.roster.fleet {
            return Err(Refusal::Invalid(format!("a roster of fleet {}, not {}", roster.fleet, self.roster.fleet)));
        }
        if !roster.signed_by(&self.ca_key) {
            return Err(Refusal::Invalid(format!(
                "roster version {} is not signed by the fleet's CA (edited by hand, or another CA's)",
                roster.version
            )));
        }
        if roster.version <= self.roster.version {
            return Err(Refusal::NotNewer { version: roster.version, held: self.roster.version });
        }
        let name = self.identity.name.as_str();
        let member = match admitted(&roster, name) {
            Ok(m) => m,
            Err(e) => return Err(Refusal::NotAdmitted(format!("{e} by roster version {}", roster.version))),
        };
        if member.public_key != self.identity.public_key {
            return Err(Refusal::NotAdmitted(format!(
                "roster version {} lists another key for {name} than its certificate's",
                roster.version
            )));
        }
        let signer = load_key(&self.key).map_err(|e| Refusal::Invalid(format!("{e:#}")))?;
        Ok(Credentials {
            dir: self.dir.clone(),
            keys: robot_keys(&roster),
            roster,
            identity: member,
            ca_cert: self.ca_cert.clone(),
            ca_key: self.ca_key.clone(),
            cert: self.cert.clone(),
            key: self.key.clone(),
            signer,
        })
    }

    /// Signs `msg` with this member's key.
    pub fn sign(&self, msg: &[u8]) -> [u8; 64] {
        self.signer.sign(msg).as_ref().try_into().expect("an Ed25519 signature is 64 bytes")
    }

    /// Whether the roster admits `robot` as a robot.
    pub fn admits_robot(&self, robot: &RobotId) -> bool {
        self.keys.contains_key(robot)
    }

    /// Whether `signature` is `member`'s over `msg`; false for a member not admitted.
    pub fn verify(&self, member: &RobotId, msg: &[u8], signature: &[u8]) -> bool {
        self.keys.get(member).is_some_and(|k| UnparsedPublicKey::new(&ED25519, k).verify(msg, signature).is_ok())
    }
}

/// Why a roster heard or read at run time was not adopted.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Refusal {
    /// The one held, or an older one: nothing to do (a peer that has not caught up).
    NotNewer { version: u64, held: u64 },
    /// Not the fleet CA's, another fleet's, or unreadable.
    Invalid(String),
    /// A valid, newer roster that no longer admits this process: it must leave.
    NotAdmitted(String),
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refusal::NotNewer { version, held } => write!(f, "roster version {version} is not newer than {held}"),
            Refusal::Invalid(why) | Refusal::NotAdmitted(why) => f.write_str(why),
        }
    }
}

/// `name`'s entry in `roster`, if it is admitted there.
fn admitted(roster: &Roster, name: &str) -> Result<Member> {
    match roster.get(name) {
        None => bail!("{name} is not a member of the fleet"),
        Some(m) if m.revoked => bail!("{name} is revoked"),
        Some(m) => Ok(m.clone()),
    }
}

/// The public keys of the robots `roster` admits: only their signatures count.
fn robot_keys(roster: &Roster) -> HashMap<RobotId, [u8; 32]> {
    roster.admitted().filter(|m| m.role == super::Role::Robot).map(|m| (m.name.clone(), m.public_key_bytes())).collect()
}

/// The roster of `dir`, refused unless the fleet's CA (`ca.crt`) signed it.
pub fn load_roster(dir: &FleetDir) -> Result<Roster> {
    let ca_pem = read_pem(&dir.ca_cert())?;
    signed_roster(dir, &parse(&ca_pem, &dir.ca_cert())?)
}

/// The roster of `dir`, refused unless `ca` signed it.
fn signed_roster(dir: &FleetDir, ca: &x509_parser::certificate::X509Certificate<'_>) -> Result<Roster> {
    let roster = Roster::load(&dir.roster())?;
    if !roster.signed_by(&ca.public_key().subject_public_key.data) {
        bail!(
            "roster {} (version {}) is not signed by the fleet's CA {}: edited by hand, or of another fleet; \
             refused (the operator's `spwi-agent fleet` commands sign it)",
            dir.roster().display(),
            roster.version,
            dir.ca_cert().display()
        );
    }
    Ok(roster)
}

fn read_pem(path: &Path) -> Result<Pem> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let (_, pem) =
        x509_parser::pem::parse_x509_pem(&bytes).map_err(|_| anyhow!("{} is not a PEM file", path.display()))?;
    Ok(pem)
}

fn parse<'a>(pem: &'a Pem, path: &Path) -> Result<x509_parser::certificate::X509Certificate<'a>> {
    pem.parse_x509().map_err(|e| anyhow!("{} is not an X.509 certificate: {e}", path.display()))
}

/// Reads a private key file, refusing one that group or others may read: a key
/// another user could have copied no longer proves who holds it.
pub(crate) fn read_private_key(path: &Path) -> Result<String> {
    use std::os::unix::fs::PermissionsExt;
    let meta = std::fs::metadata(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mode = meta.permissions().mode() & 0o777;
    if mode & 0o077 != 0 {
        bail!(
            "{}: a private key readable by group or others (mode {mode:o}); refused. Fix it with: chmod 600 {}",
            path.display(),
            path.display()
        );
    }
    std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))
}

fn load_key(path: &Path) -> Result<Ed25519KeyPair> {
    let text = read_private_key(path)?;
    let der = rcgen::KeyPair::from_pem(&text)
        .map(|k| k.serialize_der())
        .map_err(|_| anyhow!("{} is not a PEM private key", path.display()))?;
    Ed25519KeyPair::from_pkcs8_maybe_unchecked(&der)
        .map_err(|_| anyhow!("{} is not an Ed25519 key (spwi fleets use Ed25519)", path.display()))
}

#[cfg(test)]
mod tests {
    use super::super::authority::{add, init, revoke, ThrowawayFleet, Validity};
    use super::super::Role;
    use super::*;
    use spwi_proto::FleetId;
    use std::os::unix::fs::PermissionsExt;

    /// A fleet with robots r1 and r2 in a fresh directory, removed on drop.
    fn fleet(name: &str) -> ThrowawayFleet {
        let members = [("r1", Role::Robot), ("r2", Role::Robot)];
        ThrowawayFleet::create(&format!("creds-{name}"), &FleetId::new("f").unwrap(), &members).unwrap()
    }
    fn err(dir: &FleetDir, who: &str) -> String {
        format!("{:#}", Credentials::load(dir, who).unwrap_err())
    }

    #[test]
    fn a_member_loads_signs_and_is_verified_by_the_roster() {
        let t = fleet("ok");
        let c = Credentials::load(&t.dir, "r1").unwrap();
        assert_eq!(c.identity.role, Role::Robot);
        let sig = c.sign(b"tick 7");
        assert!(c.verify(&RobotId::new("r1").unwrap(), b"tick 7", &sig));
        assert!(!c.verify(&RobotId::new("r1").unwrap(), b"tick 8", &sig), "another message");
        assert!(!c.verify(&RobotId::new("r2").unwrap(), b"tick 7", &sig), "another signer");
        for (file, mode) in [(t.dir.ca_key(), 0o600), (t.dir.member_key("r1"), 0o600), (t.dir.member_cert("r1"), 0o644)]
        {
            let m = std::fs::metadata(&file).unwrap().permissions().mode() & 0o777;
            assert_eq!(m, mode, "{}", file.display());
        }
        assert!(!format!("{c:?}").contains("PRIVATE"), "Debug must not show the key");
    }

    #[test]
    fn each_bad_file_is_named() {
        let t = fleet("bad");
        let d = &t.dir;
        assert!(err(d, "r7").contains("r7 is not a member"));
        // r1 presenting r2's key
        std::fs::copy(d.member_key("r2"), d.root.join("r2.key")).unwrap();
        std::fs::remove_file(d.member_key("r1")).unwrap();
        assert!(err(d, "r1").contains("cannot read") && err(d, "r1").contains("r1.key"));
        std::fs::copy(d.root.join("r2.key"), d.member_key("r1")).unwrap();
        let e = err(d, "r1");
        assert!(e.contains("r1.key: this key does not belong to the certificate"), "{e}");
        // a certificate that is not r1's
        std::fs::copy(d.member_cert("r2"), d.member_cert("r1")).unwrap();
        assert!(err(d, "r1").contains("the certificate is for \"r2\", not \"r1\""), "{}", err(d, "r1"));
        std::fs::write(d.member_cert("r1"), "not a certificate").unwrap();
        assert!(err(d, "r1").contains("r1.crt is not a PEM file"), "{}", err(d, "r1"));
        std::fs::write(d.member_key("r2"), "-----BEGIN PRIVATE KEY-----\nAAAA\n-----END PRIVATE KEY-----\n").unwrap();
        assert!(err(d, "r2").contains("r2.key is not a PEM private key"), "{}", err(d, "r2"));
        revoke(d, "r2").unwrap();
        assert!(err(d, "r2").contains("r2 is revoked"));
        assert!(revoke(d, "r2").unwrap_err().to_string().contains("already revoked"));
        let e = add(d, &RobotId::new("r2").unwrap(), Role::Robot, Validity::days(1)).unwrap_err().to_string();
        assert!(e.contains("never reused"), "{e}");
    }

    #[test]
    fn a_private_key_others_may_read_is_refused_naming_the_file_and_the_fix() {
        use std::os::unix::fs::PermissionsExt;
        let t = fleet("modes");
        let d = &t.dir;
        std::fs::set_permissions(d.member_key("r1"), std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = err(d, "r1");
        assert!(e.contains("r1.key: a private key readable by group or others (mode 644)"), "{e}");
        assert!(e.contains(&format!("chmod 600 {}", d.member_key("r1").display())), "{e}");
        std::fs::set_permissions(d.member_key("r1"), std::fs::Permissions::from_mode(0o640)).unwrap();
        assert!(err(d, "r1").contains("mode 640"), "group-readable too");
        std::fs::set_permissions(d.member_key("r1"), std::fs::Permissions::from_mode(0o600)).unwrap();
        Credentials::load(d, "r1").unwrap();
        // the CA's key as well: nobody is admitted with it
        std::fs::set_permissions(d.ca_key(), std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = format!("{:#}", add(d, &RobotId::new("r5").unwrap(), Role::Robot, Validity::days(1)).unwrap_err());
        assert!(e.contains("ca.key: a private key readable by group or others"), "{e}");
    }

    #[test]
    fn a_roster_edited_by_hand_or_signed_by_another_ca_is_refused_naming_it() {
        let (t, other) = (fleet("signed"), fleet("signed-other"));
        let d = &t.dir;
        let v = load_roster(d).unwrap().version;
        assert_eq!(v, 3, "init, then two members added: each change a version");
        // r1's public key swapped for r2's by hand
        let mut tampered = Roster::load(&d.roster()).unwrap();
        let r2 = tampered.get("r2").unwrap().public_key.clone();
        tampered.members.iter_mut().find(|m| m.name.as_str() == "r1").unwrap().public_key = r2;
        tampered.save(&d.roster()).unwrap();
        let e = err(d, "r1");
        assert!(e.contains("fleet.toml (version 3) is not signed by the fleet's CA"), "{e}");
        // the roster of another fleet's CA, names and all alike
        std::fs::copy(other.dir.roster(), d.roster()).unwrap();
        assert!(err(d, "r1").contains("is not signed by the fleet's CA"), "another CA's roster");
        let e = add(d, &RobotId::new("r5").unwrap(), Role::Robot, Validity::days(1)).unwrap_err().to_string();
        assert!(e.contains("not signed by the fleet's CA"), "the operator's commands check it too: {e}");
    }

    #[test]
    fn a_revocation_is_signed_and_cannot_be_undone_by_hand() {
        let t = fleet("unrevoke");
        let d = &t.dir;
        revoke(d, "r2").unwrap();
        assert_eq!(load_roster(d).unwrap().version, 4);
        let mut undone = Roster::load(&d.roster()).unwrap();
        undone.members.iter_mut().for_each(|m| m.revoked = false);
        undone.save(&d.roster()).unwrap();
        assert!(err(d, "r2").contains("not signed by the fleet's CA"), "{}", err(d, "r2"));
    }

    #[test]
    fn a_certificate_of_another_ca_or_out_of_date_is_refused() {
        let (a, b) = (fleet("ca-a"), fleet("ca-b"));
        std::fs::copy(b.dir.member_cert("r1"), a.dir.member_cert("r1")).unwrap();
        assert!(err(&a.dir, "r1").contains("not signed by the fleet's CA"), "{}", err(&a.dir, "r1"));
        let now = time::OffsetDateTime::now_utc();
        let old = Validity { not_before: now - time::Duration::days(9), not_after: now - time::Duration::days(2) };
        add(&a.dir, &RobotId::new("r3").unwrap(), Role::Robot, old).unwrap();
        let e = err(&a.dir, "r3");
        assert!(e.contains("r3.crt: the certificate of r3 expired on"), "{e}");
        assert!(init(&a.dir, &FleetId::new("f").unwrap(), Validity::days(1))
            .unwrap_err()
            .to_string()
            .contains("already holds"));
    }
}
