//! `gridscada opcua trust FILE` and `opcua list`: the OPC UA server's client
//! certificates, in the store the server of `--config` (or the demo's data
//! folder) reads. The work is `gridscada_opcua::pki`'s.

use std::path::{Path, PathBuf};

use anyhow::anyhow;
use gridscada_opcua::pki::{self, ClientCert};

use crate::users::Target;

/// The certificate store of `target`'s OPC UA server.
fn store_of(target: Target) -> anyhow::Result<PathBuf> {
    match target {
        Target::Config(path) => {
            let plant = crate::settings::load_for_server(&path)?;
            let ua = plant.opcua.as_ref().ok_or_else(|| {
                anyhow!(
                    "{}: no [opcua] section, so no OPC UA certificate store",
                    plant.main_path.display()
                )
            })?;
            Ok(plant.data_dir.join(ua.pki_dir.get_ref()))
        }
        Target::DemoData(data) => {
            Ok(data.join(crate::runtime::opcua::demo_config(0).pki_dir.get_ref()))
        }
    }
}

fn show(c: &ClientCert) {
    println!("  subject:    {}", c.subject);
    println!("  thumbprint: {}", c.thumbprint);
    println!("  valid:      {} to {}", c.not_before, c.not_after);
    println!("  file:       {}", c.file.display());
}

pub fn trust(file: &Path, target: Target) -> anyhow::Result<()> {
    let store = store_of(target)?;
    let c = pki::trust(&store, file).map_err(|e| anyhow!(e))?;
    println!("trusted:");
    show(&c);
    println!("A running server accepts this client at its next connection.");
    Ok(())
}

pub fn list(target: Target) -> anyhow::Result<()> {
    let store = store_of(target)?;
    let l = pki::list(&store);
    for (what, certs) in [("trusted", &l.trusted), ("rejected", &l.rejected)] {
        println!(
            "{what} ({}, {}):",
            certs.len(),
            store
                .join(if what == "trusted" {
                    pki::TRUSTED_DIR
                } else {
                    pki::REJECTED_DIR
                })
                .display()
        );
        for c in certs {
            show(c);
        }
    }
    for u in &l.unreadable {
        eprintln!("unreadable: {u}");
    }
    Ok(())
}
