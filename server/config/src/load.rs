//! Reading the configuration files.
//!
//! Each top-level section, and each `[[device]]`, `[[tag]]` and `[[panel]]`
//! entry, is deserialized on its own, so one bad entry does not hide the
//! problems of the others: `gridscada check` reports them all.

use std::io;
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde_spanned::Spanned;
use toml::de::{DeTable, DeValue, ValueDeserializer};

use crate::diag::{Diagnostic, SourceFile};
use crate::model::*;
use crate::overrides::{has_plaintext_password, Warning, ENV_STORAGE_PASSWORD, ENV_STORAGE_URL};
use crate::validate;

/// A checked plant configuration.
#[derive(Debug, Clone)]
pub struct Plant {
    /// The main file.
    pub main_path: PathBuf,
    /// The data folder: `[server] data_dir`, a relative one taken from the
    /// main file's folder (like `tag_files`), unless replaced from the
    /// environment or the command line (see [`crate::apply_env`]).
    pub data_dir: PathBuf,
    /// What works but should not be left so (`gridscada check` prints them,
    /// `serve` logs them), e.g. a plaintext password in the storage URL.
    pub warnings: Vec<Warning>,
    /// HTTPS, from `[server.tls]` with its file paths resolved like
    /// `data_dir` (or replaced from the environment); `None`: plain HTTP.
    pub tls: Option<TlsFiles>,
    pub server: ServerConfig,
    pub storage: StorageConfig,
    pub devices: Vec<DeviceConfig>,
    pub tags: Vec<TagConfig>,
    pub panels: Vec<PanelConfig>,
    pub microgrid: Option<MicrogridConfig>,
    /// `[mqtt]`: the Sparkplug B northbound, if configured.
    pub mqtt: Option<MqttConfig>,
    /// `[opcua]`: the OPC UA server, if configured.
    pub opcua: Option<OpcUaConfig>,
    /// `[iec104_server]`: the IEC 104 controlled station, if configured.
    pub iec104_server: Option<Iec104ServerConfig>,
    /// `[redundancy]`: one of a redundant pair, if configured.
    pub redundancy: Option<RedundancyConfig>,
    /// `[[notify]]`: alarm notification routes (none: no alarm leaves the
    /// server).
    pub notify: Vec<NotifyConfig>,
    /// `[[suppression]]`: configured suppression rules (besides the panels'
    /// built-in ones).
    pub suppression: Vec<SuppressionConfig>,
    /// `[reports]`: when reports are made on their own.
    pub reports: ReportsConfig,
    /// `[network]`: the switching network, if configured.
    pub network: Option<NetworkConfig>,
    /// `[hmi]`: decimals and date format on the HMI.
    pub hmi: HmiConfig,
    /// Positions of the tags and devices by name, made at the first lookup.
    index: NameIndex,
}

/// Where each tag and device name sits in [`Plant::tags`] and
/// [`Plant::devices`], so a lookup by name is not a scan of a million tags
/// (start-up looks up every tag once: a scan each would be quadratic).
/// Built at the first lookup. It holds positions only, hashed by the name
/// they point at, not a copy of every name. A hit is checked against the
/// list; a miss scans the list only if its length changed since the index
/// was made, so a plant whose lists were changed after loading (tests do)
/// still answers right, and a name that is not configured (a device's
/// status tag, a remote tag) costs one probe, not a scan.
#[derive(Debug, Clone, Default)]
struct NameIndex {
    tags: std::sync::OnceLock<Positions>,
    devices: std::sync::OnceLock<Positions>,
}

#[derive(Debug, Clone)]
struct Positions {
    hasher: std::hash::RandomState,
    table: hashbrown::HashTable<u32>,
    /// The list's length when the index was made.
    len: usize,
}

/// Each name's position (the first, should a name repeat).
fn positions<T>(items: &[T], name_of: impl Fn(&T) -> &String) -> Positions {
    use std::hash::BuildHasher;
    let hasher = std::hash::RandomState::new();
    let mut table = hashbrown::HashTable::with_capacity(items.len());
    let hash = |i: &u32| hasher.hash_one(name_of(&items[*i as usize]).as_str());
    for (i, item) in items.iter().enumerate() {
        let name = name_of(item);
        let h = hasher.hash_one(name.as_str());
        let Ok(i) = u32::try_from(i) else { break };
        if table
            .find(h, |j: &u32| name_of(&items[*j as usize]) == name)
            .is_none()
        {
            table.insert_unique(h, i, hash);
        }
    }
    Positions {
        hasher,
        table,
        len: items.len(),
    }
}

/// The item named `name`: by the index when it still holds there, else
/// (when the list changed since) by a scan.
fn lookup<'a, T>(
    index: &Positions,
    items: &'a [T],
    name: &str,
    name_of: impl Fn(&T) -> &String,
) -> Option<&'a T> {
    use std::hash::BuildHasher;
    let h = index.hasher.hash_one(name);
    let hit = index.table.find(h, |j: &u32| {
        items
            .get(*j as usize)
            .is_some_and(|item| name_of(item) == name)
    });
    if let Some(&i) = hit {
        return items.get(i as usize);
    }
    if items.len() == index.len {
        return None;
    }
    items.iter().find(|item| name_of(item) == name)
}

/// Where HTTPS takes its certificate and key, and its other settings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TlsFiles {
    /// The certificate chain, PEM.
    pub cert: PathBuf,
    /// The private key, PEM.
    pub key: PathBuf,
    /// The plain-HTTP address that redirects to HTTPS, if any.
    pub redirect_http: Option<std::net::SocketAddr>,
    /// HSTS `max-age` in seconds; 0: no HSTS.
    pub hsts_max_age_s: u64,
}

impl Plant {
    pub fn device(&self, name: &str) -> Option<&DeviceConfig> {
        let index = self
            .index
            .devices
            .get_or_init(|| positions(&self.devices, |d| d.name.get_ref()));
        lookup(index, &self.devices, name, |d| d.name.get_ref())
    }
    pub fn tag(&self, name: &str) -> Option<&TagConfig> {
        let index = self
            .index
            .tags
            .get_or_init(|| positions(&self.tags, |t| t.name.get_ref()));
        lookup(index, &self.tags, name, |t| t.name.get_ref())
    }

    /// The engineering limits `(min, max)` a write to `name` must respect:
    /// the tag's own `min`/`max`, else, for a microgrid unit's setpoint, its
    /// ratings (PV and wind 0..rated, storage -max_charge..max_discharge,
    /// diesel 0..max). Either bound may be open.
    pub fn write_limits(&self, name: &str) -> (Option<f64>, Option<f64>) {
        let tag = self.tag(name);
        let configured = |l: Option<&serde_spanned::Spanned<f64>>| l.map(|v| *v.get_ref());
        let (mut lo, mut hi) = (
            configured(tag.and_then(|t| t.min.as_ref())),
            configured(tag.and_then(|t| t.max.as_ref())),
        );
        // A unit's setpoint is `{prefix}.Setpoint_kW` (`UnitConfig::io`);
        // matched by its prefix, not by building every unit's names per tag.
        let setpoint_of = name
            .rsplit_once('.')
            .filter(|(_, last)| *last == crate::model::SETPOINT_KW)
            .map(|(prefix, _)| prefix);
        if let Some(u) = setpoint_of.and_then(|prefix| {
            self.microgrid
                .iter()
                .flat_map(|m| &m.units)
                .find(|u| u.prefix.get_ref() == prefix)
        }) {
            let (ulo, uhi) = match u.kind {
                crate::UnitKind::Pv | crate::UnitKind::Wind => (0.0, u.rated_kw),
                crate::UnitKind::Storage => (-u.max_charge_kw, u.max_discharge_kw),
                crate::UnitKind::Diesel => (0.0, u.max_kw),
            };
            lo = lo.or(Some(ulo));
            hi = hi.or(Some(uhi));
        }
        (lo, hi)
    }

    /// The configured tags as the tag database knows them.
    pub fn tag_metas(&self) -> impl Iterator<Item = gridscada_tagdb::TagMeta> + '_ {
        self.tags.iter().map(|t| {
            gridscada_tagdb::TagMeta::new(t.name.get_ref().as_str(), t.value_kind())
                .describe(t.description.clone())
                .units(t.units.clone())
                .writable(*t.writable.get_ref())
        })
    }
}

/// Loads and checks the configuration at `path`: a main file, or a folder
/// holding `gridscada.toml`.
pub fn load_path(path: &Path) -> Result<Plant, Vec<Diagnostic>> {
    let main = if path.is_dir() {
        path.join("gridscada.toml")
    } else {
        path.to_path_buf()
    };
    load_with(&main, &|p: &Path| std::fs::read_to_string(p))
}

/// Loads and checks the configuration whose main file is `main`, reading
/// files through `read` (the binary passes embedded text for the demo plant).
pub fn load_with(
    main: &Path,
    read: &dyn Fn(&Path) -> io::Result<String>,
) -> Result<Plant, Vec<Diagnostic>> {
    let mut diags = Vec::new();
    let main_text = read(main).map_err(|e| {
        vec![Diagnostic {
            file: main.to_path_buf(),
            line: 0,
            column: 0,
            message: format!("cannot read the main configuration file: {}", io_reason(&e)),
        }]
    })?;
    let main_file = SourceFile::new(main, main_text);
    let parsed_main = parse_main(&main_file, &mut diags);

    let base = main.parent().unwrap_or(Path::new(""));
    let mut files = vec![];
    let mut devices = vec![];
    let mut broken_devices = std::collections::HashSet::new();
    let mut tags = vec![];
    if let Some(main_cfg) = &parsed_main {
        for tf in &main_cfg.tag_files {
            let path = base.join(tf.get_ref());
            match read(&path) {
                Ok(text) => {
                    let file = SourceFile::new(&path, text);
                    let idx = files.len() + 1; // 0 is the main file
                    let (tf, broken) = parse_tag_file(&file, &mut diags);
                    broken_devices.extend(broken);
                    devices.extend(tf.devices.into_iter().map(|d| (idx, d)));
                    tags.extend(tf.tags.into_iter().map(|t| (idx, t)));
                    files.push(file);
                }
                Err(e) => diags.push(main_file.error_at(
                    tf.span(),
                    format!(
                        "cannot read tag file '{}': {}",
                        path.display(),
                        io_reason(&e)
                    ),
                )),
            }
        }
    }
    let mut all_files = vec![main_file];
    all_files.extend(files);

    let Some(main_cfg) = parsed_main else {
        return Err(diags);
    };
    validate::check(
        &all_files,
        &main_cfg,
        &devices,
        &broken_devices,
        &tags,
        &mut diags,
    );
    if !diags.is_empty() {
        diags.sort_by(|a, b| (&a.file, a.line, a.column).cmp(&(&b.file, b.line, b.column)));
        diags.dedup();
        return Err(diags);
    }
    let mut warnings = Vec::new();
    let url = &main_cfg.storage.url;
    if has_plaintext_password(url.get_ref()) {
        warnings.push(Warning(all_files[0].error_at(
            url.span(),
            format!(
                "[storage] url holds a plaintext password; keep secrets out of the file: give \
                 the password in {} (or the whole URL in {}) in the server's environment",
                ENV_STORAGE_PASSWORD.name, ENV_STORAGE_URL.name
            ),
        )));
    }
    if let Some(password) = main_cfg.mqtt.as_ref().and_then(|m| m.password.as_ref()) {
        warnings.push(Warning(all_files[0].error_at(
            password.span(),
            format!(
                "[mqtt] password is in the file; keep secrets out of it: give it in {} in the server's environment",
                crate::overrides::ENV_MQTT_PASSWORD.name
            ),
        )));
    }
    Ok(Plant {
        main_path: main.to_path_buf(),
        data_dir: base.join(&main_cfg.server.data_dir),
        tls: main_cfg.server.tls.as_ref().map(|t| TlsFiles {
            cert: base.join(t.cert.get_ref()),
            key: base.join(t.key.get_ref()),
            // Checked by validate.
            redirect_http: t
                .redirect_http
                .as_ref()
                .and_then(|a| a.get_ref().parse().ok()),
            hsts_max_age_s: *t.hsts_max_age_s.get_ref(),
        }),
        warnings,
        server: main_cfg.server,
        storage: main_cfg.storage,
        devices: devices.into_iter().map(|(_, d)| d).collect(),
        tags: tags.into_iter().map(|(_, t)| t).collect(),
        panels: main_cfg.panels,
        microgrid: main_cfg.microgrid,
        mqtt: main_cfg.mqtt,
        opcua: main_cfg.opcua,
        iec104_server: main_cfg.iec104_server,
        redundancy: main_cfg.redundancy,
        notify: main_cfg.notify,
        suppression: main_cfg.suppression,
        reports: main_cfg.reports,
        network: main_cfg.network,
        hmi: main_cfg.hmi,
        index: NameIndex::default(),
    })
}

fn io_reason(e: &io::Error) -> String {
    match e.kind() {
        io::ErrorKind::NotFound => "no such file".into(),
        io::ErrorKind::PermissionDenied => "permission denied".into(),
        _ => e.to_string(),
    }
}

/// Parses a file into its top-level table, reporting syntax errors.
fn parse_root<'a>(file: &'a SourceFile, diags: &mut Vec<Diagnostic>) -> Option<DeTable<'a>> {
    let (root, errors) = DeTable::parse_recoverable(&file.text);
    if !errors.is_empty() {
        for e in errors {
            diags.push(locate(file, &e, "TOML syntax error: "));
        }
        return None;
    }
    Some(root.into_inner())
}

fn locate(file: &SourceFile, e: &toml::de::Error, prefix: &str) -> Diagnostic {
    let message = format!("{prefix}{}", e.message().trim());
    match e.span() {
        Some(span) => file.error_at(span, message),
        None => file.error(message),
    }
}

fn de<T: DeserializeOwned>(
    file: &SourceFile,
    value: &Spanned<DeValue<'_>>,
    what: &str,
    diags: &mut Vec<Diagnostic>,
) -> Option<T> {
    match T::deserialize(ValueDeserializer::from(value.clone())) {
        Ok(v) => Some(v),
        Err(e) => {
            let mut d = locate(file, &e, &format!("{what}: "));
            if e.span().is_none() {
                let (line, column) = file.line_col(value.span().start);
                d.line = line;
                d.column = column;
            }
            diags.push(d);
            None
        }
    }
}

/// Deserializes every table of an array of tables (`[[tag]]`) on its own.
fn de_each<T: DeserializeOwned>(
    file: &SourceFile,
    value: &Spanned<DeValue<'_>>,
    section: &str,
    diags: &mut Vec<Diagnostic>,
) -> Vec<T> {
    let Some(array) = value.get_ref().as_array() else {
        diags.push(file.error_at(
            value.span(),
            format!("'{section}' must be an array of tables ([[{section}]])"),
        ));
        return vec![];
    };
    array
        .iter()
        .enumerate()
        .filter_map(|(i, entry)| {
            let label = entry_label(entry)
                .map(|n| format!("{section} '{n}'"))
                .unwrap_or_else(|| format!("{section} #{}", i + 1));
            de(file, entry, &label, diags)
        })
        .collect()
}

/// The `name` or `id` of an entry, to say which one an error is in.
fn entry_label(entry: &Spanned<DeValue<'_>>) -> Option<String> {
    let table = entry.get_ref().as_table()?;
    ["name", "id"].iter().find_map(|key| {
        table
            .iter()
            .find(|(k, _)| k.get_ref().as_ref() == *key)
            .and_then(|(_, v)| v.get_ref().as_str().map(str::to_owned))
    })
}

fn parse_main(file: &SourceFile, diags: &mut Vec<Diagnostic>) -> Option<MainFile> {
    let root = parse_root(file, diags)?;
    let mut tag_files = None;
    let mut server = ServerConfig::default();
    let mut storage = StorageConfig::default();
    let mut panels = vec![];
    let mut microgrid = None;
    let mut mqtt = None;
    let mut opcua = None;
    let mut iec104_server = None;
    let mut redundancy = None;
    let mut notify = vec![];
    let mut suppression = vec![];
    let mut reports = ReportsConfig::default();
    let mut network = None;
    let mut hmi = HmiConfig::default();
    let before = diags.len();
    for (key, value) in root.iter() {
        match key.get_ref().as_ref() {
            "tag_files" => tag_files = de::<Vec<Spanned<String>>>(file, value, "tag_files", diags),
            "server" => server = de(file, value, "[server]", diags).unwrap_or_default(),
            "storage" => storage = de(file, value, "[storage]", diags).unwrap_or_default(),
            "panel" => panels = de_each(file, value, "panel", diags),
            "microgrid" => microgrid = de(file, value, "[microgrid]", diags),
            "mqtt" => mqtt = de(file, value, "[mqtt]", diags),
            "opcua" => opcua = de(file, value, "[opcua]", diags),
            "iec104_server" => iec104_server = de(file, value, "[iec104_server]", diags),
            "redundancy" => redundancy = de(file, value, "[redundancy]", diags),
            "notify" => notify = de_each(file, value, "notify", diags),
            "suppression" => suppression = de_each(file, value, "suppression", diags),
            "reports" => reports = de(file, value, "[reports]", diags).unwrap_or_default(),
            "network" => network = de(file, value, "[network]", diags),
            "hmi" => hmi = de(file, value, "[hmi]", diags).unwrap_or_default(),
            other => diags.push(file.error_at(
                key.span(),
                format!(
                    "unknown key '{other}' in the main file; expected one of tag_files, server, storage, panel, microgrid, mqtt, opcua, iec104_server, redundancy, notify, suppression, reports, network, hmi"
                ),
            )),
        }
    }
    // A central Sparkplug host may leave out `tag_files`: its tags come
    // from the births of edge nodes.
    let central = mqtt.as_ref().is_some_and(|m: &MqttConfig| m.host.is_some());
    let tag_files = match tag_files {
        None if central => Some(Vec::new()),
        other => other,
    };
    let Some(tag_files) = tag_files else {
        if diags.len() == before {
            diags.push(file.error_at(0..0, "missing 'tag_files': list the tag files of the plant"));
        }
        return None;
    };
    Some(MainFile {
        tag_files,
        server,
        storage,
        panels,
        microgrid,
        mqtt,
        opcua,
        iec104_server,
        redundancy,
        notify,
        suppression,
        reports,
        network,
        hmi,
    })
}

/// A tag file's devices and tags, and the names of the `[[device]]` entries
/// that did not parse (already reported: their tags are not reported again
/// as naming an unknown device).
fn parse_tag_file(file: &SourceFile, diags: &mut Vec<Diagnostic>) -> (TagFile, Vec<String>) {
    let Some(root) = parse_root(file, diags) else {
        return (TagFile::default(), vec![]);
    };
    let mut out = TagFile::default();
    let mut broken = vec![];
    for (key, value) in root.iter() {
        match key.get_ref().as_ref() {
            "device" => {
                out.devices = de_each(file, value, "device", diags);
                let named: Vec<String> = value
                    .get_ref()
                    .as_array()
                    .map(|a| a.iter().filter_map(entry_label).collect())
                    .unwrap_or_default();
                broken.extend(named.into_iter().filter(|n| {
                    !out.devices
                        .iter()
                        .any(|d: &DeviceConfig| d.name.get_ref() == n)
                }));
            }
            "tag" => out.tags = de_each(file, value, "tag", diags),
            other => diags.push(file.error_at(
                key.span(),
                format!("unknown key '{other}' in a tag file; expected [[device]] or [[tag]]"),
            )),
        }
    }
    (out, broken)
}
