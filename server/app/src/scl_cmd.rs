//! `gridscada scl import FILE`: an SCL file's IEDs as tag files of a
//! plant, one per IED (the import itself is `gridscada_scl::import`'s),
//! and a main file to run them when the folder has none.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, bail, Context};

pub struct Import {
    pub file: PathBuf,
    pub ieds: Vec<String>,
    pub out: PathBuf,
    pub write_role: String,
    pub addresses: Vec<String>,
    pub force: bool,
    /// Also draw a screen per bay (`screens/*.json`).
    pub screens: bool,
}

pub fn import(args: Import) -> anyhow::Result<()> {
    let started = Instant::now();
    let filter = gridscada_scl::Filter {
        ieds: args.ieds.clone(),
    };
    let scl = gridscada_scl::read_path(&args.file, &filter).map_err(|e| anyhow!("{e}"))?;
    for want in &args.ieds {
        if !scl.ieds.iter().any(|i| &i.name == want) {
            bail!(
                "{}: no IED '{want}' (it has: {})",
                args.file.display(),
                scl.all_ied_names.join(", ")
            );
        }
    }
    if scl.ieds.is_empty() {
        bail!("{}: no IED in the file", args.file.display());
    }
    let mut overrides = std::collections::HashMap::new();
    for a in &args.addresses {
        let (ied, addr) = a
            .split_once('=')
            .ok_or_else(|| anyhow!("--address '{a}': expected IED=host:port"))?;
        overrides.insert(ied.to_string(), addr.to_string());
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let scl_ref = relative_to(&args.file, &args.out);
    let mut written = Vec::new();
    let mut imported = Vec::new();
    for ied in &scl.ieds {
        let mut imp = gridscada_scl::import::import(&scl, ied);
        if let Some(a) = overrides.get(&ied.name) {
            imp.address = a.clone();
        }
        let file_name = format!("{}.toml", ied.name);
        let path = args.out.join(&file_name);
        if path.exists() && !args.force {
            bail!(
                "{} exists; --force replaces it (hand edits in it are lost)",
                path.display()
            );
        }
        let text = gridscada_scl::import::render(&imp, &scl_ref, &args.write_role);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
        let controls = imp.tags.iter().filter(|t| t.ctl_model.is_some()).count();
        println!(
            "{}: {} tags ({controls} controllable), {} report control blocks, address {} -> {}",
            ied.name,
            imp.tags.len(),
            imp.reports.len(),
            imp.address,
            path.display()
        );
        written.push(file_name);
        imported.push(imp);
    }
    if args.screens {
        draw_screens(&scl, &imported, &args.out, args.force)?;
    }
    let main = args.out.join("gridscada.toml");
    if main.exists() {
        let text = std::fs::read_to_string(&main).unwrap_or_default();
        let missing: Vec<&String> = written
            .iter()
            .filter(|f| !text.contains(&format!("\"{f}\"")))
            .collect();
        if !missing.is_empty() {
            println!(
                "add {} to tag_files in {}",
                missing
                    .iter()
                    .map(|f| format!("\"{f}\""))
                    .collect::<Vec<_>>()
                    .join(", "),
                main.display()
            );
        }
    } else {
        let files = written
            .iter()
            .map(|f| format!("\"{f}\""))
            .collect::<Vec<_>>()
            .join(", ");
        std::fs::write(
            &main,
            format!(
                "# A plant of IEC 61850 IEDs, made by `gridscada scl import {}`.\n\
                 # Run it with `gridscada serve --config {}`; check it with `gridscada check {}`.\n\n\
                 tag_files = [{files}]\n\n[server]\nhttp = \"127.0.0.1:8080\"\ndata_dir = \"data\"\n\n\
                 [storage]\nurl = \"sqlite://gridscada.db\"\n",
                args.file.display(),
                args.out.display(),
                args.out.display()
            ),
        )
        .with_context(|| format!("writing {}", main.display()))?;
        println!("wrote {} (tag_files = [{files}])", main.display());
    }
    println!(
        "read {} IED(s) of {} in {:.2} s",
        scl.ieds.len(),
        scl.all_ied_names.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// A screen per bay (or per IED where the SCL has no bays for it): its
/// switch positions as breakers with Open and Close buttons for the
/// controllable ones, then its other values, each with the IED's time.
fn draw_screens(
    scl: &gridscada_scl::Scl,
    imported: &[gridscada_scl::import::Imported],
    out: &Path,
    force: bool,
) -> anyhow::Result<()> {
    use gridscada_config::screen::{Element, ElementKind, Screen, MAX_ELEMENTS};
    let dir = out.join("screens");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut ids = std::collections::HashSet::new();
    for (name, tags) in gridscada_scl::import::bays(scl, imported) {
        let id = screen_id(&name, &mut ids);
        let mut elements = vec![Element {
            x: 20,
            y: 10,
            w: 900,
            h: 40,
            kind: ElementKind::Text {
                text: name.clone(),
                size: Some(22),
            },
        }];
        // "CSWI1 Pos": the logical node and data object, as the engineer knows them.
        let label = |t: &gridscada_scl::import::ImportedTag| {
            let do_path = t.name.splitn(4, '.').nth(3).unwrap_or(&t.name).to_string();
            format!(
                "{} {}",
                t.ln,
                do_path
                    .split_once('.')
                    .map_or(do_path.as_str(), |(_, rest)| rest)
            )
        };
        let (switches, values): (Vec<_>, Vec<_>) = tags
            .iter()
            .partition(|(_, t)| t.data_type == "bool" && t.reference.ends_with(".Pos.stVal"));
        for (i, (_, t)) in switches.iter().enumerate() {
            let x = 20 + (i as i64 % 5) * 230;
            let y = 70 + (i as i64 / 5) * 130;
            elements.push(Element {
                x,
                y,
                w: 200,
                h: 50,
                kind: ElementKind::Breaker {
                    tag: t.name.clone(),
                    label: label(t),
                    time: true,
                },
            });
            if t.ctl_model.is_some() {
                for (dx, text, v) in [(0, "Open", false), (100, "Close", true)] {
                    elements.push(Element {
                        x: x + dx,
                        y: y + 58,
                        w: 95,
                        h: 32,
                        kind: ElementKind::Button {
                            tag: t.name.clone(),
                            label: text.to_string(),
                            value: serde_json::Value::Bool(v),
                        },
                    });
                }
            }
        }
        let top = 70 + (switches.len().div_ceil(5) as i64) * 130;
        for (i, (_, t)) in values.iter().enumerate() {
            elements.push(Element {
                x: 20 + (i as i64 % 4) * 290,
                y: top + (i as i64 / 4) * 60,
                w: 270,
                h: 50,
                kind: ElementKind::Value {
                    tag: t.name.clone(),
                    label: label(t),
                    digits: None,
                    units: None,
                    time: true,
                },
            });
        }
        elements.truncate(MAX_ELEMENTS);
        let height = elements.iter().map(|e| e.y + e.h).max().unwrap_or(0) + 40;
        let screen = Screen {
            id: id.clone(),
            name,
            version: 0,
            width: 1200,
            height: height.clamp(700, 10_000),
            elements,
        };
        let path = dir.join(format!("{id}.json"));
        if path.exists() && !force {
            bail!("{} exists; --force replaces it", path.display());
        }
        std::fs::write(&path, serde_json::to_string_pretty(&screen)?)
            .with_context(|| format!("writing {}", path.display()))?;
        println!(
            "screen '{}': {} elements -> {}",
            screen.name,
            screen.elements.len(),
            path.display()
        );
    }
    Ok(())
}

/// A screen id from a bay's name (lowercase letters, digits, '-', at most
/// 64), unique among `taken`.
fn screen_id(name: &str, taken: &mut std::collections::HashSet<String>) -> String {
    let mut id = String::new();
    for c in name.chars().flat_map(char::to_lowercase) {
        if c.is_ascii_alphanumeric() {
            id.push(c);
        } else if !id.ends_with('-') && !id.is_empty() {
            id.push('-');
        }
    }
    let base: String = id.trim_end_matches('-').chars().take(56).collect();
    let base = if base.is_empty() {
        "bay".to_string()
    } else {
        base
    };
    let mut id = base.clone();
    let mut n = 2;
    while !taken.insert(id.clone()) {
        id = format!("{base}-{n}");
        n += 1;
    }
    id
}

/// `file` as a path from `dir` (absolute when they share no root).
fn relative_to(file: &Path, dir: &Path) -> String {
    let (Ok(file), Ok(dir)) = (std::fs::canonicalize(file), std::fs::canonicalize(dir)) else {
        return file.display().to_string();
    };
    let common = file
        .components()
        .zip(dir.components())
        .take_while(|(a, b)| a == b)
        .count();
    if common <= 1 {
        return file.display().to_string();
    }
    let mut rel = PathBuf::new();
    for _ in dir.components().skip(common) {
        rel.push("..");
    }
    for c in file.components().skip(common) {
        rel.push(c);
    }
    rel.display().to_string()
}
