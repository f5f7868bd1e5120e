//! The fleet's certificate authority: `spwi-agent fleet init | add | revoke`.
//!
//! Every key is Ed25519 (rcgen over ring, the crypto rustls already uses inside Zenoh):
//! one key per member serves both its TLS certificate and the signatures on the ballots
//! peers relay for it. Keys are written 0600 and never logged; the CA key only has to
//! stay where members are admitted, every other file is public.

use super::roster::{encode_hex, Member, Role, Roster};
use super::FleetDir;
use anyhow::{bail, Context, Result};
use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair, KeyUsagePurpose,
    PKCS_ED25519,
};
use ring::signature::Ed25519KeyPair;
use spwi_proto::{FleetId, RobotId};
use std::io::Write;
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;
use time::{Duration, OffsetDateTime};

/// How long a certificate is valid.
#[derive(Debug, Clone, Copy)]
pub struct Validity {
    pub not_before: OffsetDateTime,
    pub not_after: OffsetDateTime,
}

impl Validity {
    /// From an hour ago (clocks of a fleet drift) for `days` days.
    pub fn days(days: u32) -> Validity {
        let now = OffsetDateTime::now_utc();
        Validity { not_before: now - Duration::hours(1), not_after: now + Duration::days(days.into()) }
    }
}

/// `fleet init`: a new CA and an empty roster in `dir` (created; refused if it already
/// holds a fleet).
pub fn init(dir: &FleetDir, fleet: &FleetId, validity: Validity) -> Result<()> {
    if dir.roster().exists() || dir.ca_key().exists() {
        bail!("{} already holds a fleet (fleet.toml or ca.key exists); refusing to overwrite it", dir.root.display());
    }
    std::fs::create_dir_all(dir.members()).with_context(|| format!("cannot create {}", dir.members().display()))?;
    let key = KeyPair::generate_for(&PKCS_ED25519)?;
    let mut params = CertificateParams::new(Vec::<String>::new())?;
    params.distinguished_name.push(DnType::CommonName, format!("spwi fleet {fleet} CA"));
    params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    (params.not_before, params.not_after) = (validity.not_before, validity.not_after);
    let cert = params.self_signed(&key)?;
    write_new(&dir.ca_key(), key.serialize_pem().as_bytes(), 0o600)?;
    write_new(&dir.ca_cert(), cert.pem().as_bytes(), 0o644)?;
    save_signed(dir, &mut Roster::new(fleet.clone()), &ca_signer(&key, dir)?)
}

/// The CA's key as a signer of rosters.
fn ca_signer(key: &KeyPair, dir: &FleetDir) -> Result<Ed25519KeyPair> {
    Ed25519KeyPair::from_pkcs8_maybe_unchecked(&key.serialize_der())
        .map_err(|_| anyhow::anyhow!("{} is not an Ed25519 key (spwi fleets use Ed25519)", dir.ca_key().display()))
}

/// The CA's key, read from `dir` (refused if others may read it).
fn read_ca_key(dir: &FleetDir) -> Result<KeyPair> {
    KeyPair::from_pem(&super::credentials::read_private_key(&dir.ca_key())?)
        .with_context(|| format!("{} is not a PEM private key", dir.ca_key().display()))
}

/// Writes `roster` as its next version, signed with the CA's key.
fn save_signed(dir: &FleetDir, roster: &mut Roster, ca: &Ed25519KeyPair) -> Result<()> {
    roster.sign_next(|bytes| ca.sign(bytes).as_ref().to_vec());
    roster.save(&dir.roster())
}

/// `fleet add`: a key and a certificate for `name` signed by the fleet's CA, and its
/// roster entry. A name already in the roster is refused, revoked or not (a revoked
/// name given a new certificate would be admitted again under the same common name).
pub fn add(dir: &FleetDir, name: &RobotId, role: Role, validity: Validity) -> Result<Member> {
    let mut roster = super::credentials::load_roster(dir)?;
    if let Some(m) = roster.get(name.as_str()) {
        let state = if m.revoked { "revoked" } else { "admitted" };
        bail!("{name} is already in the roster ({state} {}); names are never reused", m.role.as_str());
    }
    let ca_pem = read(&dir.ca_cert())?;
    let ca_key = read_ca_key(dir)?;
    let signer = ca_signer(&ca_key, dir)?;
    let issuer = Issuer::from_ca_cert_pem(&ca_pem, ca_key)
        .with_context(|| format!("{} is not a PEM certificate", dir.ca_cert().display()))?;

    let key = KeyPair::generate_for(&PKCS_ED25519)?;
    let mut params = CertificateParams::new(vec![name.to_string()])?;
    params.distinguished_name.push(DnType::CommonName, name.as_str());
    params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
    params.extended_key_usages = vec![ExtendedKeyUsagePurpose::ServerAuth, ExtendedKeyUsagePurpose::ClientAuth];
    (params.not_before, params.not_after) = (validity.not_before, validity.not_after);
    let cert = params.signed_by(&key, &issuer)?;
    write_new(&dir.member_key(name.as_str()), key.serialize_pem().as_bytes(), 0o600)?;
    write_new(&dir.member_cert(name.as_str()), cert.pem().as_bytes(), 0o644)?;

    let member = Member {
        name: name.clone(),
        role,
        public_key: encode_hex(key.public_key_raw()),
        not_after: rfc3339(validity.not_after),
        revoked: false,
    };
    roster.members.push(member.clone());
    save_signed(dir, &mut roster, &signer)?;
    Ok(member)
}

/// A new fleet in `dir` with `members` admitted at once.
pub fn create(dir: &FleetDir, fleet: &FleetId, members: &[(&str, Role)], validity: Validity) -> Result<()> {
    init(dir, fleet, validity)?;
    for (name, role) in members {
        add(dir, &RobotId::new(*name)?, *role, validity)?;
    }
    Ok(())
}

/// A fleet in a fresh directory under the system's temporary one, removed when dropped:
/// for a secured bench, and for tests.
pub struct ThrowawayFleet {
    pub dir: FleetDir,
}

impl ThrowawayFleet {
    /// `label` keeps the directories of concurrent users apart (with the process id).
    pub fn create(label: &str, fleet: &FleetId, members: &[(&str, Role)]) -> Result<ThrowawayFleet> {
        let dir = FleetDir::new(std::env::temp_dir().join(format!("spwi-fleet-{label}-{}", std::process::id())));
        let _ = std::fs::remove_dir_all(&dir.root);
        create(&dir, fleet, members, Validity::days(1))?;
        Ok(ThrowawayFleet { dir })
    }

    /// A fleet of the world and `robots`, the members a simulated fleet needs.
    pub fn with_world(label: &str, fleet: &FleetId, robots: &[RobotId]) -> Result<ThrowawayFleet> {
        let members: Vec<(&str, Role)> =
            std::iter::once(("world", Role::World)).chain(robots.iter().map(|r| (r.as_str(), Role::Robot))).collect();
        Self::create(label, fleet, &members)
    }
}

impl Drop for ThrowawayFleet {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir.root);
    }
}

/// `fleet revoke`: marks `name` revoked in the roster. Every process that adopts the
/// new roster (`super::live`) denies it everything; its files are left for the record.
pub fn revoke(dir: &FleetDir, name: &str) -> Result<()> {
    let mut roster = super::credentials::load_roster(dir)?;
    let Some(m) = roster.members.iter_mut().find(|m| m.name.as_str() == name) else {
        bail!("{name} is not in the roster {}", dir.roster().display());
    };
    if m.revoked {
        bail!("{name} is already revoked");
    }
    m.revoked = true;
    save_signed(dir, &mut roster, &ca_signer(&read_ca_key(dir)?, dir)?)
}

pub(crate) fn rfc3339(t: OffsetDateTime) -> String {
    format!(
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}Z",
        t.year(),
        u8::from(t.month()),
        t.day(),
        t.hour(),
        t.minute(),
        t.second()
    )
}

fn read(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))
}

/// Creates `path` with `mode` from the start (a key is never readable by others, not
/// even for a moment); refuses to overwrite.
fn write_new(path: &Path, bytes: &[u8], mode: u32) -> Result<()> {
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(mode)
        .open(path)
        .with_context(|| format!("cannot create {}", path.display()))?;
    f.write_all(bytes).with_context(|| format!("cannot write {}", path.display()))
}
