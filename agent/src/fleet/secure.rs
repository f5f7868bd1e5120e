//! A Zenoh config that admits only the fleet's members: mutual TLS on every link and
//! default-deny access control generated from the roster.
//!
//! **TLS.** TLS and QUIC (TLS 1.3 inside, the same certificates and checks) are the
//! only link protocols (so neither scouting nor a stray `tcp/` endpoint can fall back to
//! plain TCP); `tcp/` endpoints of the given config are taken as `tls/` on the same
//! address, so one Zenoh file serves open and secured fleets; `quic/` endpoints stay.
//! Both ends present their certificate and check the other's against the fleet's CA
//! (`enable_mtls`). Host names are not checked (robots meet on addresses, not names):
//! identity is the certificate's common name, and the access rules are written on it.
//! Links close when a peer's certificate expires.
//!
//! **Access control.** Zenoh 1.10 has no per-certificate templating, so each admitted
//! member gets its own subject (its common name) and rule set:
//! - a robot may put only under `spwi/<fleet>/robot/<name>/**` and hold (and answer for)
//!   only `spwi/<fleet>/alive/<name>`;
//! - the world may put detections for any robot and `spwi/<fleet>/world/**`;
//! - a robot or the world may say the roster it holds on `spwi/<fleet>/roster/<name>`
//!   (it counts only if the fleet's CA signed it, [`super::live`]);
//! - a router may forward anything of the fleet;
//! - an observer may say nothing;
//! - every member may subscribe and ask for liveliness anywhere in the fleet, and is
//!   sent anything of the fleet.
//!
//! Anything else, and anyone else (a revoked member, a certificate of no member), is
//! denied. Zenoh 1.10 cannot change these rules in a running session, so a process that
//! adopts a new roster reopens its session with the new rules ([`super::live`]). Zenoh checks these rules on the last hop only: a message is judged by the
//! identity of the link it arrives on. In a full peer mesh that link is the author's,
//! so the rules hold. A router forwards others' messages under its own name, so it must
//! be trusted: it runs these same rules on what it receives and is the only role
//! allowed to forward. An untrusted router (one without this roster) must never be on
//! the path; there is none in spwi's own deployment.

use super::credentials::Credentials;
use super::roster::Role;
use anyhow::{anyhow, Result};
use serde_json::{json, Value};
use spwi_proto::keys::{self, Topic};

/// Turns `c` into a secured config for `creds`' identity.
pub fn apply(c: &mut zenoh::Config, creds: &Credentials) -> Result<()> {
    let path = |p: &std::path::Path| Value::String(p.display().to_string());
    let settings = [
        ("transport/link/protocols", json!(["tls", "quic"])),
        ("transport/link/tls/root_ca_certificate", path(&creds.ca_cert)),
        ("transport/link/tls/listen_certificate", path(&creds.cert)),
        ("transport/link/tls/listen_private_key", path(&creds.key)),
        ("transport/link/tls/connect_certificate", path(&creds.cert)),
        ("transport/link/tls/connect_private_key", path(&creds.key)),
        ("transport/link/tls/enable_mtls", json!(true)),
        ("transport/link/tls/verify_name_on_connect", json!(false)),
        ("transport/link/tls/close_link_on_expiration", json!(true)),
        ("access_control", access_control(creds)),
    ];
    for (key, value) in settings {
        set(c, key, &value)?;
    }
    for key in ["listen/endpoints", "connect/endpoints"] {
        let current: Value = serde_json::from_str(&c.get_json(key).map_err(|e| anyhow!("{key}: {e}"))?)?;
        set(c, key, &to_tls(current))?;
    }
    Ok(())
}

fn set(c: &mut zenoh::Config, key: &str, value: &Value) -> Result<()> {
    c.insert_json5(key, &value.to_string()).map_err(|e| anyhow!("zenoh setting {key}: {e}"))
}

/// `tcp/` endpoints as `tls/`, in a list or in a per-mode map of lists.
fn to_tls(endpoints: Value) -> Value {
    match endpoints {
        Value::String(s) => Value::String(match s.strip_prefix("tcp/") {
            Some(rest) => format!("tls/{rest}"),
            None => s,
        }),
        Value::Array(a) => Value::Array(a.into_iter().map(to_tls).collect()),
        Value::Object(o) => Value::Object(o.into_iter().map(|(k, v)| (k, to_tls(v))).collect()),
        other => other,
    }
}

/// The `access_control` section for the roster of `creds`.
pub fn access_control(creds: &Credentials) -> Value {
    let fleet = &creds.roster.fleet;
    let everything = keys::everything(fleet);
    let (mut rules, mut subjects, mut policies) = (Vec::new(), Vec::new(), Vec::new());
    rules.push(json!({
        "id": "members-listen",
        "messages": ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
        "flows": ["ingress", "egress"],
        "permission": "allow",
        "key_exprs": [everything],
    }));
    rules.push(json!({
        "id": "members-are-told",
        "messages": ["put", "liveliness_token", "reply"],
        "flows": ["egress"],
        "permission": "allow",
        "key_exprs": [everything],
    }));
    for m in creds.roster.admitted() {
        let name = m.name.as_str();
        let may_say: Vec<String> = match m.role {
            Role::Robot => {
                vec![keys::robot_everything(fleet, &m.name), keys::alive(fleet, &m.name), keys::roster(fleet, &m.name)]
            }
            Role::World => vec![
                keys::all_robots(fleet, Topic::Detections),
                keys::world_everything(fleet),
                keys::roster(fleet, &m.name),
            ],
            Role::Router => vec![everything.clone()],
            Role::Observer => vec![],
        };
        let mut own_rules = vec![json!("members-listen"), json!("members-are-told")];
        if !may_say.is_empty() {
            rules.push(json!({
                "id": format!("says-{name}"),
                "messages": ["put", "liveliness_token", "reply"],
                "flows": ["ingress"],
                "permission": "allow",
                "key_exprs": may_say,
            }));
            own_rules.push(json!(format!("says-{name}")));
        }
        subjects.push(json!({ "id": format!("member-{name}"), "cert_common_names": [name] }));
        policies.push(json!({ "rules": own_rules, "subjects": [format!("member-{name}")] }));
    }
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tcp_endpoints_become_tls_on_the_same_address() {
        let v = json!({"peer": ["tcp/[::]:0", "udp/1.2.3.4:5"], "router": ["tcp/0.0.0.0:7447"]});
        assert_eq!(to_tls(v), json!({"peer": ["tls/[::]:0", "udp/1.2.3.4:5"], "router": ["tls/0.0.0.0:7447"]}));
        assert_eq!(to_tls(json!(["tcp/10.0.0.2:7447"])), json!(["tls/10.0.0.2:7447"]));
    }
}
