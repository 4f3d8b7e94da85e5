//! The client certificates of the store, as async-opcua 0.19 keeps them:
//! `PKI/trusted/` and `PKI/rejected/`, one DER file per certificate named
//! `CN [THUMBPRINT].der`. The server looks in both folders at every secure
//! session, so a certificate trusted here is accepted at the client's next
//! connection, without a restart. It refuses a certificate that has a file
//! in `rejected/` even when `trusted/` has it too, so trusting removes the
//! rejected copy, and [`RejectedSweep`] removes one an operator's copy left.

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use opcua::crypto::{CertificateStore, X509};

/// The folder async-opcua reads trusted client certificates from.
pub const TRUSTED_DIR: &str = "trusted";
/// The folder it writes unknown client certificates to.
pub const REJECTED_DIR: &str = "rejected";

/// A client certificate, as `opcua trust` and `opcua list` show it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClientCert {
    pub subject: String,
    /// SHA-1 of the DER, in hex: what OPC UA tools show.
    pub thumbprint: String,
    pub not_before: String,
    pub not_after: String,
    /// Its file in the store.
    pub file: PathBuf,
}

/// The store's client certificates; unreadable files with why.
#[derive(Debug, Default)]
pub struct Listing {
    pub trusted: Vec<ClientCert>,
    pub rejected: Vec<ClientCert>,
    pub unreadable: Vec<String>,
}

/// Reads a certificate in DER or PEM, whatever the file is called.
fn read(file: &Path) -> Result<X509, String> {
    let bytes = std::fs::read(file).map_err(|e| format!("{}: {e}", file.display()))?;
    let parsed = if bytes.trim_ascii_start().starts_with(b"-----BEGIN") {
        X509::from_pem(&bytes)
    } else {
        X509::from_der(&bytes)
    };
    parsed.map_err(|_| format!("{}: not an X.509 certificate (DER or PEM)", file.display()))
}

fn describe(cert: &X509, file: PathBuf) -> ClientCert {
    let time = |t: Result<_, _>| match t {
        Ok(t) => format!("{}", t),
        Err(_) => "unreadable".to_string(),
    };
    ClientCert {
        subject: cert.subject_name(),
        thumbprint: cert.thumbprint().as_hex_string(),
        not_before: time(cert.not_before()),
        not_after: time(cert.not_after()),
        file,
    }
}

/// Trusts the client certificate in `file` (DER or PEM): writes it to
/// `pki/trusted/` under the name the server looks for, and removes it from
/// `pki/rejected/`.
pub fn trust(pki: &Path, file: &Path) -> Result<ClientCert, String> {
    let cert = read(file)?;
    let der = cert
        .to_der()
        .map_err(|_| format!("{}: the certificate cannot be encoded", file.display()))?;
    let name = CertificateStore::cert_file_name(&cert);
    let trusted = pki.join(TRUSTED_DIR);
    std::fs::create_dir_all(&trusted)
        .map_err(|e| format!("cannot make {}: {e}", trusted.display()))?;
    let target = trusted.join(&name);
    // Written aside and renamed: the server never reads half a file.
    let part = trusted.join(format!(".{name}.part"));
    std::fs::write(&part, &der).map_err(|e| format!("cannot write {}: {e}", part.display()))?;
    std::fs::rename(&part, &target)
        .map_err(|e| format!("cannot write {}: {e}", target.display()))?;
    let rejected = pki.join(REJECTED_DIR).join(&name);
    match std::fs::remove_file(&rejected) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => {
            return Err(format!(
                "trusted, but {} cannot be removed and still blocks it: {e}",
                rejected.display()
            ))
        }
    }
    Ok(describe(&cert, target))
}

/// The trusted and rejected client certificates, by subject.
pub fn list(pki: &Path) -> Listing {
    let mut out = Listing::default();
    for (dir, into) in [(TRUSTED_DIR, 0), (REJECTED_DIR, 1)] {
        let Ok(entries) = std::fs::read_dir(pki.join(dir)) else {
            continue;
        };
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file() && !is_part(p))
            .collect();
        files.sort();
        for f in files {
            match read(&f) {
                Ok(c) => {
                    let c = describe(&c, f);
                    if into == 0 {
                        out.trusted.push(c);
                    } else {
                        out.rejected.push(c);
                    }
                }
                Err(e) => out.unreadable.push(e),
            }
        }
    }
    out
}

fn is_part(p: &Path) -> bool {
    p.file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.starts_with('.'))
}

/// Removes from `rejected/` the certificates an operator trusted by copying
/// them to `trusted/` (the server would go on refusing them). Looks only
/// when `trusted/` changed since the last look: it runs before every
/// accepted connection.
pub struct RejectedSweep {
    pki: PathBuf,
    seen: Option<SystemTime>,
}

impl RejectedSweep {
    pub fn new(pki: &Path) -> RejectedSweep {
        RejectedSweep {
            pki: pki.to_path_buf(),
            seen: None,
        }
    }

    /// The names removed from `rejected/`.
    pub fn run(&mut self) -> Vec<String> {
        let trusted = self.pki.join(TRUSTED_DIR);
        let changed = std::fs::metadata(&trusted).and_then(|m| m.modified()).ok();
        if changed.is_none() || changed == self.seen {
            return vec![];
        }
        self.seen = changed;
        let Ok(entries) = std::fs::read_dir(self.pki.join(REJECTED_DIR)) else {
            return vec![];
        };
        let mut removed = vec![];
        for e in entries.flatten() {
            let name = e.file_name();
            if trusted.join(&name).is_file() && std::fs::remove_file(e.path()).is_ok() {
                removed.push(name.to_string_lossy().into_owned());
            }
        }
        removed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A self-signed client certificate, as a client makes one.
    fn client_cert() -> X509 {
        let data = opcua::crypto::X509Data {
            key_size: 2048,
            common_name: "asyncua".into(),
            organization: "tests".into(),
            organizational_unit: "".into(),
            country: "EU".into(),
            state: "".into(),
            alt_host_names: vec!["urn:tests:client".to_string(), "localhost".to_string()].into(),
            certificate_duration_days: 30,
        };
        let (cert, _) = X509::cert_and_pkey(&data).unwrap();
        cert
    }

    /// The server's own check of a client certificate.
    fn accepted(store: &CertificateStore, cert: &X509) -> bool {
        store
            .validate_application_instance_cert(
                cert,
                opcua::crypto::SecurityPolicy::Basic256Sha256,
                None,
                None,
            )
            .is_ok()
    }

    #[test]
    fn trust_moves_a_rejected_certificate_where_the_server_reads_it() {
        let dir = tempfile::tempdir().unwrap();
        let pki = dir.path();
        let cert = client_cert();
        let name = CertificateStore::cert_file_name(&cert);
        // Where async-opcua itself puts an unknown client's certificate.
        let store = CertificateStore::new(pki);
        store.ensure_pki_path().unwrap();
        let rejected = store.store_rejected_cert(&cert).unwrap();
        assert_eq!(rejected, pki.join(REJECTED_DIR).join(&name));
        let listed = list(pki);
        assert_eq!(listed.rejected.len(), 1);
        assert!(listed.trusted.is_empty());

        let got = trust(pki, &rejected).unwrap();
        assert_eq!(got.thumbprint, cert.thumbprint().as_hex_string());
        assert!(got.subject.contains("asyncua"), "{}", got.subject);
        assert_eq!(got.file, pki.join(TRUSTED_DIR).join(&name));
        assert!(!rejected.exists());
        let listed = list(pki);
        assert_eq!((listed.trusted.len(), listed.rejected.len()), (1, 0));
        // The server's own check now passes.
        assert!(accepted(&store, &cert));
    }

    #[test]
    fn trust_reads_pem_and_refuses_what_is_no_certificate() {
        let dir = tempfile::tempdir().unwrap();
        let made = rcgen::generate_simple_self_signed(vec!["localhost".into()]).unwrap();
        let pem = dir.path().join("client.crt");
        std::fs::write(&pem, made.cert.pem()).unwrap();
        let pki = dir.path().join("pki");
        let got = trust(&pki, &pem).unwrap();
        assert_eq!(std::fs::read(&got.file).unwrap(), made.cert.der().to_vec());
        let junk = dir.path().join("junk.der");
        std::fs::write(&junk, b"hello").unwrap();
        let e = trust(&pki, &junk).unwrap_err();
        assert!(
            e.contains("junk.der") && e.contains("not an X.509 certificate"),
            "{e}"
        );
        assert_eq!(list(&pki).trusted.len(), 1);
    }

    #[test]
    fn a_copy_left_in_rejected_is_swept_once_trusted() {
        let dir = tempfile::tempdir().unwrap();
        let pki = dir.path();
        let cert = client_cert();
        let store = CertificateStore::new(pki);
        store.ensure_pki_path().unwrap();
        let rejected = store.store_rejected_cert(&cert).unwrap();
        let mut sweep = RejectedSweep::new(pki);
        assert!(sweep.run().is_empty());
        // The operator copies instead of moving.
        let name = rejected.file_name().unwrap();
        std::fs::copy(&rejected, pki.join(TRUSTED_DIR).join(name)).unwrap();
        assert!(!accepted(&store, &cert));
        assert_eq!(sweep.run().len(), 1);
        assert!(!rejected.exists());
        assert!(accepted(&store, &cert));
    }
}
