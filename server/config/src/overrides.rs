//! Settings given outside the configuration files: the `GRIDSCADA_*`
//! environment variables, for secrets and for what differs between
//! machines (the database URL and password, the listen address, the data
//! folder, the metrics token, the TLS certificate and key, the public origin
//! and base path behind a reverse proxy), and the warning about a plaintext
//! password left in the file.
//!
//! The environment is read through a lookup function, so this stays pure
//! (the binary passes `std::env::var`, tests a map). A value that is not
//! usable is an error naming the variable, never its secret value.
//! Precedence, highest first: a command-line flag (`serve --http/--data`,
//! applied by the binary), the environment, the file.

use std::path::PathBuf;

use serde_spanned::Spanned;

use crate::diag::Diagnostic;
use crate::load::{Plant, TlsFiles};

/// A `GRIDSCADA_*` environment variable and the setting it replaces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EnvVar {
    pub name: &'static str,
    /// The setting of `gridscada.toml` it replaces (for messages and docs).
    pub setting: &'static str,
}

pub const ENV_STORAGE_URL: EnvVar = EnvVar {
    name: "GRIDSCADA_STORAGE_URL",
    setting: "[storage] url",
};
pub const ENV_STORAGE_PASSWORD: EnvVar = EnvVar {
    name: "GRIDSCADA_STORAGE_PASSWORD",
    setting: "the password of [storage] url",
};
pub const ENV_HTTP: EnvVar = EnvVar {
    name: "GRIDSCADA_HTTP",
    setting: "[server] http",
};
pub const ENV_DATA_DIR: EnvVar = EnvVar {
    name: "GRIDSCADA_DATA_DIR",
    setting: "[server] data_dir",
};
pub const ENV_METRICS_TOKEN: EnvVar = EnvVar {
    name: "GRIDSCADA_METRICS_TOKEN",
    setting: "[server] metrics_token",
};

pub const ENV_TLS_CERT: EnvVar = EnvVar {
    name: "GRIDSCADA_TLS_CERT",
    setting: "[server.tls] cert",
};
pub const ENV_TLS_KEY: EnvVar = EnvVar {
    name: "GRIDSCADA_TLS_KEY",
    setting: "[server.tls] key",
};

pub const ENV_BASE_PATH: EnvVar = EnvVar {
    name: "GRIDSCADA_BASE_PATH",
    setting: "[server] base_path",
};
pub const ENV_PUBLIC_ORIGIN: EnvVar = EnvVar {
    name: "GRIDSCADA_PUBLIC_ORIGIN",
    setting: "[server] public_origin",
};

pub const ENV_MQTT_PASSWORD: EnvVar = EnvVar {
    name: "GRIDSCADA_MQTT_PASSWORD",
    setting: "[mqtt] password",
};

/// Every variable [`apply_env`] reads, in the order it applies them.
pub const ENV_VARS: [EnvVar; 10] = [
    ENV_STORAGE_URL,
    ENV_STORAGE_PASSWORD,
    ENV_HTTP,
    ENV_DATA_DIR,
    ENV_METRICS_TOKEN,
    ENV_TLS_CERT,
    ENV_TLS_KEY,
    ENV_BASE_PATH,
    ENV_PUBLIC_ORIGIN,
    ENV_MQTT_PASSWORD,
];

/// Replaces the file's settings with the `GRIDSCADA_*` variables that `get`
/// finds (see [`ENV_VARS`]). A relative `GRIDSCADA_DATA_DIR` is taken from
/// the working directory, like a command-line path. Returns the variables
/// applied (names only: their values may be secret), or every problem, each
/// naming its variable.
pub fn apply_env(
    plant: &mut Plant,
    get: &dyn Fn(&str) -> Option<String>,
) -> Result<Vec<&'static str>, Vec<Diagnostic>> {
    let mut applied = Vec::new();
    let mut errors = Vec::new();
    let mut fail = |var: EnvVar, message: String| {
        errors.push(env_error(format!(
            "{} (replacing {}): {message}",
            var.name, var.setting
        )))
    };
    // Each variable: unset is fine, set but empty is a mistake.
    let value = |var: EnvVar, errors: &mut dyn FnMut(EnvVar, String)| -> Option<String> {
        let v = get(var.name)?;
        if v.trim().is_empty() {
            errors(
                var,
                "set but empty; unset it to keep the file's setting".into(),
            );
            return None;
        }
        Some(v)
    };

    if let Some(url) = value(ENV_STORAGE_URL, &mut fail) {
        match storage_url_problem(&url) {
            Some(why) => fail(ENV_STORAGE_URL, why),
            None => {
                plant.storage.url = Spanned::new(0..0, url);
                applied.push(ENV_STORAGE_URL.name);
            }
        }
    }
    if let Some(password) = value(ENV_STORAGE_PASSWORD, &mut fail) {
        match with_password(plant.storage.url.get_ref(), &password) {
            Ok(url) => {
                plant.storage.url = Spanned::new(0..0, url);
                applied.push(ENV_STORAGE_PASSWORD.name);
            }
            Err(why) => fail(ENV_STORAGE_PASSWORD, why),
        }
    }
    if let Some(http) = value(ENV_HTTP, &mut fail) {
        if http.parse::<std::net::SocketAddr>().is_ok() {
            plant.server.http = Spanned::new(0..0, http);
            applied.push(ENV_HTTP.name);
        } else {
            fail(
                ENV_HTTP,
                format!("'{http}' is not an address like 127.0.0.1:8080"),
            );
        }
    }
    if let Some(dir) = value(ENV_DATA_DIR, &mut fail) {
        plant.data_dir = PathBuf::from(dir);
        applied.push(ENV_DATA_DIR.name);
    }
    if let Some(token) = value(ENV_METRICS_TOKEN, &mut fail) {
        plant.server.metrics_token = Some(token);
        applied.push(ENV_METRICS_TOKEN.name);
    }
    // The certificate and key: a relative path is taken from the working
    // directory, like GRIDSCADA_DATA_DIR. Without [server.tls] in the file,
    // both must be given, and HTTPS starts with the defaults of the rest.
    let cert = value(ENV_TLS_CERT, &mut fail).map(PathBuf::from);
    let key = value(ENV_TLS_KEY, &mut fail).map(PathBuf::from);
    match (&mut plant.tls, cert, key) {
        (_, None, None) => {}
        (Some(tls), cert, key) => {
            if let Some(cert) = cert {
                tls.cert = cert;
                applied.push(ENV_TLS_CERT.name);
            }
            if let Some(key) = key {
                tls.key = key;
                applied.push(ENV_TLS_KEY.name);
            }
        }
        (None, Some(cert), Some(key)) => {
            plant.tls = Some(TlsFiles {
                cert,
                key,
                redirect_http: None,
                hsts_max_age_s: crate::model::DEFAULT_HSTS_MAX_AGE_S,
            });
            applied.extend([ENV_TLS_CERT.name, ENV_TLS_KEY.name]);
        }
        (None, Some(_), None) => fail(
            ENV_TLS_CERT,
            format!(
                "the file has no [server.tls]; set {} too, to the certificate's private key",
                ENV_TLS_KEY.name
            ),
        ),
        (None, None, Some(_)) => fail(
            ENV_TLS_KEY,
            format!(
                "the file has no [server.tls]; set {} too, to the certificate",
                ENV_TLS_CERT.name
            ),
        ),
    }
    if let Some(base) = value(ENV_BASE_PATH, &mut fail) {
        match crate::normal_base_path(&base) {
            Ok(_) => {
                plant.server.base_path = Some(Spanned::new(0..0, base));
                applied.push(ENV_BASE_PATH.name);
            }
            Err(why) => fail(ENV_BASE_PATH, why),
        }
    }
    if let Some(origin) = value(ENV_PUBLIC_ORIGIN, &mut fail) {
        match crate::normal_public_origin(&origin) {
            Ok(_) => {
                plant.server.public_origin = Some(Spanned::new(0..0, origin));
                applied.push(ENV_PUBLIC_ORIGIN.name);
            }
            Err(why) => fail(ENV_PUBLIC_ORIGIN, why),
        }
    }
    if let Some(password) = value(ENV_MQTT_PASSWORD, &mut fail) {
        match &mut plant.mqtt {
            Some(mqtt) if mqtt.username.is_some() => {
                mqtt.password = Some(Spanned::new(0..0, password));
                applied.push(ENV_MQTT_PASSWORD.name);
            }
            Some(_) => fail(
                ENV_MQTT_PASSWORD,
                "[mqtt] has no username for this password".into(),
            ),
            None => fail(
                ENV_MQTT_PASSWORD,
                "the configuration has no [mqtt] section".into(),
            ),
        }
    }
    if errors.is_empty() {
        Ok(applied)
    } else {
        Err(errors)
    }
}

/// A problem of the environment rather than of a file.
fn env_error(message: String) -> Diagnostic {
    Diagnostic {
        file: PathBuf::from("environment"),
        line: 0,
        column: 0,
        message,
    }
}

/// Why `url` cannot be a storage URL (the scheme is all that is shown: the
/// rest may hold a password).
fn storage_url_problem(url: &str) -> Option<String> {
    if url.starts_with("sqlite:") || postgres_rest(url).is_some() {
        None
    } else {
        let scheme = url.split(':').next().unwrap_or_default();
        Some(format!(
            "a URL of scheme '{scheme}:' is not storage; it must start with sqlite:, postgres:// or postgresql://"
        ))
    }
}

/// The part of a PostgreSQL URL after `postgres://` or `postgresql://`.
fn postgres_rest(url: &str) -> Option<(&str, &str)> {
    ["postgres://", "postgresql://"]
        .iter()
        .find_map(|s| url.strip_prefix(s).map(|rest| (*s, rest)))
}

/// A PostgreSQL URL split at its user info: (scheme, user info, rest), the
/// user info `None` when there is no `@` before the host.
fn split_userinfo(url: &str) -> Option<(&str, Option<&str>, &str)> {
    let (scheme, rest) = postgres_rest(url)?;
    let authority_end = rest.find(['/', '?']).unwrap_or(rest.len());
    match rest[..authority_end].rfind('@') {
        Some(at) => Some((scheme, Some(&rest[..at]), &rest[at + 1..])),
        None => Some((scheme, None, rest)),
    }
}

/// Whether a storage URL carries a password in clear: `user:PASSWORD@` or a
/// `password=` query parameter.
pub fn has_plaintext_password(url: &str) -> bool {
    let Some((_, userinfo, rest)) = split_userinfo(url) else {
        return false;
    };
    let in_userinfo = userinfo
        .and_then(|u| u.split_once(':'))
        .is_some_and(|(_, p)| !p.is_empty());
    let in_query = rest.split_once('?').is_some_and(|(_, q)| {
        q.split('&').any(|kv| {
            kv.split_once('=')
                .is_some_and(|(k, v)| k == "password" && !v.is_empty())
        })
    });
    in_userinfo || in_query
}

/// `url` (PostgreSQL, with a user name) with its password set to `password`,
/// percent-encoded.
fn with_password(url: &str, password: &str) -> Result<String, String> {
    let Some((scheme, userinfo, rest)) = split_userinfo(url) else {
        return Err(
            "the storage URL is not PostgreSQL (postgres://…); SQLite has no password".into(),
        );
    };
    let user = userinfo
        .map(|u| u.split_once(':').map_or(u, |(user, _)| user))
        .filter(|u| !u.is_empty())
        .ok_or_else(|| {
            "the storage URL names no user to go with the password; write it as postgres://USER@host/db"
                .to_string()
        })?;
    Ok(format!(
        "{scheme}{user}:{}@{rest}",
        percent_encode(password)
    ))
}

/// Percent-encodes everything but the unreserved characters of RFC 3986.
fn percent_encode(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for b in s.bytes() {
        if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_' | b'~') {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// A warning: something that works but should not be left as it is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Warning(pub Diagnostic);

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let d = &self.0;
        if d.line == 0 {
            write!(f, "{}: warning: {}", d.file.display(), d.message)
        } else {
            write!(
                f,
                "{}:{}:{}: warning: {}",
                d.file.display(),
                d.line,
                d.column,
                d.message
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passwords_are_found_and_set() {
        for (url, has) in [
            ("postgres://scada:s3cret@db/scada", true),
            (
                "postgresql://scada:s3cret@db:5432/scada?sslmode=require",
                true,
            ),
            ("postgres://scada@db/scada", false),
            ("postgres://scada:@db/scada", false),
            ("postgres://db/scada?user=scada&password=x", true),
            ("postgres://db/scada?user=scada", false),
            ("sqlite://gridscada.db", false),
            // An @ in the path or query is not user info.
            ("postgres://db/scada?application_name=a@b", false),
        ] {
            assert_eq!(has_plaintext_password(url), has, "{url}");
        }
        assert_eq!(
            with_password("postgres://scada@db/scada", "p@ss:w/rd%").unwrap(),
            "postgres://scada:p%40ss%3Aw%2Frd%25@db/scada"
        );
        assert_eq!(
            with_password("postgresql://scada:old@db:5432/x?sslmode=require", "new").unwrap(),
            "postgresql://scada:new@db:5432/x?sslmode=require"
        );
        assert!(with_password("postgres://db/scada", "x")
            .unwrap_err()
            .contains("no user"));
        assert!(with_password("sqlite://x.db", "x")
            .unwrap_err()
            .contains("not PostgreSQL"));
    }
}
