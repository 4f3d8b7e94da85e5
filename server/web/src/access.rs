//! Which screens exist and which tags a caller may read.
//!
//! **Owns:** the screen catalog of the loaded plant (built-in screens, one
//! per configured panel, the microgrid screens when there is a microgrid, and
//! the screens users drew), the in-memory library of user screens, the
//! default screen access of each role, and tag read access derived from the
//! screens a caller may open (see `docs/ACCESS.md`). **Must not touch:** SQL
//! (the library is loaded from and saved through the store by the handlers).
//!
//! Nothing here names a plant: every screen and tag set comes from the
//! configuration and the screens that were saved.

use std::collections::{BTreeMap, HashSet};
use std::sync::Arc;

use gridscada_config::screen::{Screen, CUSTOM_PREFIX};
use gridscada_config::{Plant, Role};
use parking_lot::RwLock;
use serde::Serialize;

use crate::auth::Principal;

/// Built-in screens that every plant has, after the plant-specific ones, in
/// toolbar order (by group), with their labels. The Simulation screen is
/// listed only by a server that runs simulators.
const TOOLS: &[(&str, &str, ScreenGroup)] = &[
    ("alarms", "Alarms", ScreenGroup::Alarms),
    ("events", "Events", ScreenGroup::Alarms),
    ("trends", "Trends", ScreenGroup::Trends),
    ("tags", "Tags", ScreenGroup::Engineering),
    ("devices", "Devices", ScreenGroup::Engineering),
    ("editor", "Screen editor", ScreenGroup::Engineering),
    (SIMULATION, "Simulation", ScreenGroup::Engineering),
    ("users", "Users", ScreenGroup::Administration),
    ("reports", "Reports", ScreenGroup::Administration),
    ("alarmkpi", "Alarm KPIs", ScreenGroup::Administration),
];

/// The switching network's single-line screen (a plant with `[network]`).
pub const NETWORK: &str = "network";

/// Screens only an Administrator's group gets by default.
const ADMIN_ONLY: &[&str] = &["users", "editor", SIMULATION];

/// The Simulation (training) panel: only in a server that runs simulators.
pub const SIMULATION: &str = "simulation";

/// Screens a Supervisor's group gets by default, an Operator's not: alarm
/// rationalisation (the ISA-18.2 KPIs) and reports are the supervisors' work.
const SUPERVISOR_UP: &[&str] = &["alarmkpi", "reports"];

/// What kind of screen an entry is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ScreenKind {
    Builtin,
    Panel,
    Custom,
}

/// Where a screen sits in the HMI's navigation (docs/HMI_STYLE.md,
/// "Navigation"): the catalog lists the groups in this order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ScreenGroup {
    /// The plant: main, panels, microgrid, network, drawn screens.
    Process,
    /// Alarms and events.
    Alarms,
    Trends,
    /// Tags, devices, the screen editor, the simulation panel.
    Engineering,
    /// Users, reports, the alarm KPIs.
    Administration,
}

/// One screen of the catalog.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScreenEntry {
    /// The id used in screen access lists and HMI routes.
    pub id: String,
    pub label: String,
    pub kind: ScreenKind,
    pub group: ScreenGroup,
    /// The panel's id, for a panel screen.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub panel: Option<String>,
    /// The saved version, for a user screen.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub version: Option<i64>,
}

/// The screens users drew, as last saved, by id (without `custom:`).
#[derive(Default)]
pub struct ScreenLibrary {
    screens: RwLock<BTreeMap<String, Arc<Screen>>>,
    /// Whether this server runs simulators (`demo`, replay), and so has the
    /// Simulation screen; set where the router is built.
    simulation: std::sync::atomic::AtomicBool,
}

impl ScreenLibrary {
    pub fn new(screens: impl IntoIterator<Item = Screen>) -> Self {
        let lib = ScreenLibrary::default();
        for s in screens {
            lib.put(s);
        }
        lib
    }
    pub fn get(&self, id: &str) -> Option<Arc<Screen>> {
        self.screens.read().get(id).cloned()
    }
    pub fn put(&self, screen: Screen) {
        self.screens
            .write()
            .insert(screen.id.clone(), Arc::new(screen));
    }
    pub fn remove(&self, id: &str) {
        self.screens.write().remove(id);
    }
    pub fn all(&self) -> Vec<Arc<Screen>> {
        self.screens.read().values().cloned().collect()
    }
    /// Offers the Simulation screen (a server with simulators) or not.
    pub fn set_simulation(&self, on: bool) {
        self.simulation
            .store(on, std::sync::atomic::Ordering::Relaxed);
    }
    pub fn has_simulation(&self) -> bool {
        self.simulation.load(std::sync::atomic::Ordering::Relaxed)
    }
}

/// Every screen of this plant, in toolbar order.
pub fn catalog(plant: &Plant, library: &ScreenLibrary) -> Vec<ScreenEntry> {
    let builtin = |id: &str, label: &str, group: ScreenGroup| ScreenEntry {
        id: id.into(),
        label: label.into(),
        kind: ScreenKind::Builtin,
        group,
        panel: None,
        version: None,
    };
    let mut out = vec![];
    if !plant.panels.is_empty() {
        out.push(builtin("main", "Main", ScreenGroup::Process));
    }
    for p in &plant.panels {
        let id = p.id.get_ref();
        out.push(ScreenEntry {
            id: id.clone(),
            label: if p.name.trim().is_empty() {
                id.clone()
            } else {
                p.name.clone()
            },
            kind: ScreenKind::Panel,
            group: ScreenGroup::Process,
            panel: Some(id.clone()),
            version: None,
        });
    }
    if plant.microgrid.is_some() {
        out.push(builtin("microgrid", "Microgrid", ScreenGroup::Process));
        out.push(builtin("units", "Units", ScreenGroup::Process));
    }
    if plant.network.is_some() {
        out.push(builtin(NETWORK, "Network", ScreenGroup::Process));
    }
    for s in library.all() {
        out.push(ScreenEntry {
            id: s.access_id(),
            label: s.name.clone(),
            kind: ScreenKind::Custom,
            group: ScreenGroup::Process,
            panel: None,
            version: Some(s.version),
        });
    }
    out.extend(
        TOOLS
            .iter()
            .filter(|(id, ..)| *id != SIMULATION || library.has_simulation())
            .map(|(id, label, group)| builtin(id, label, *group)),
    );
    out
}

/// Whether `id` names a screen of this plant.
pub fn screen_exists(plant: &Plant, library: &ScreenLibrary, id: &str) -> bool {
    match id.strip_prefix(CUSTOM_PREFIX) {
        Some(custom) => library.get(custom).is_some(),
        None => catalog(plant, library).iter().any(|e| e.id == id),
    }
}

/// The screens a group named after a role may open before an administrator
/// changes it. Guests and displays see the plant's overview screens and the
/// alarms, never the engineering screens (tags, devices) or the tools of
/// administrators.
pub fn default_screens(plant: &Plant, library: &ScreenLibrary, role: Role) -> Vec<String> {
    catalog(plant, library)
        .into_iter()
        .filter(|e| match role {
            Role::Administrator => true,
            Role::Supervisor => !ADMIN_ONLY.contains(&e.id.as_str()),
            Role::Operator => ![ADMIN_ONLY, SUPERVISOR_UP]
                .concat()
                .contains(&e.id.as_str()),
            Role::Guest | Role::Display => {
                matches!(e.kind, ScreenKind::Builtin)
                    && ["main", "microgrid", NETWORK, "alarms", "trends"].contains(&e.id.as_str())
            }
        })
        .map(|e| e.id)
        .collect()
}

/// The tags a caller may read: the union of the tags of the screens their
/// group may open. The engineering screens (tags, devices) open every tag.
/// Every logged-in caller may read the devices' `Comm.*` status tags, which
/// the header's communication light shows on every screen.
#[derive(Debug, Clone, Default)]
pub struct Readable {
    all: bool,
    prefixes: Vec<String>,
    names: HashSet<String>,
    comm_prefixes: Vec<String>,
}

impl Readable {
    /// What `who` may read in `plant` with the screens in `library`.
    pub fn of(who: &Principal, plant: &Plant, library: &ScreenLibrary) -> Readable {
        let mut r = Readable::default();
        if !who.is_logged_in() {
            return r;
        }
        r.comm_prefixes = plant
            .devices
            .iter()
            .map(|d| format!("{}.Comm.", d.name.get_ref()))
            .collect();
        let panel_prefix = |id: &str| {
            plant
                .panels
                .iter()
                .find(|p| p.id.get_ref() == id)
                .map(|p| format!("{}.", p.prefix.get_ref()))
        };
        for screen in &who.screens {
            match screen.as_str() {
                "tags" | "devices" => r.all = true,
                "main" => r.prefixes.extend(
                    plant
                        .panels
                        .iter()
                        .map(|p| format!("{}.", p.prefix.get_ref())),
                ),
                "microgrid" | "units" => {
                    if let Some(mg) = &plant.microgrid {
                        r.prefixes
                            .extend(mg.units.iter().map(|u| format!("{}.", u.prefix.get_ref())));
                        r.names.insert(mg.demand_tag.get_ref().clone());
                        if let Some((load, _)) = mg.demand_tag.get_ref().rsplit_once('.') {
                            r.prefixes.push(format!("{load}."));
                        }
                        r.prefixes
                            .push(format!("{}.", gridscada_control::dispatch::tags::PREFIX));
                    }
                }
                other => {
                    if let Some(custom) = other.strip_prefix(CUSTOM_PREFIX) {
                        if let Some(s) = library.get(custom) {
                            r.names.extend(s.tags().into_iter().map(String::from));
                            r.prefixes
                                .extend(s.panels().into_iter().filter_map(panel_prefix));
                        }
                    } else if let Some(p) = panel_prefix(other) {
                        r.prefixes.push(p);
                    }
                }
            }
        }
        r.prefixes.sort();
        r.prefixes.dedup();
        r
    }

    /// The network screen's tags: the network's own (under its prefix)
    /// and its devices' status and command tags.
    pub fn add_network(&mut self, net: &gridscada_network::Network) {
        self.prefixes.push(format!("{}.", net.prefix));
        self.names.extend(
            net.input_tags()
                .map(String::from)
                .chain(net.command.iter().flatten().map(|c| c.tag().to_string())),
        );
    }

    /// Everything (for tests and tools).
    pub fn everything() -> Readable {
        Readable {
            all: true,
            ..Default::default()
        }
    }

    pub fn all(&self) -> bool {
        self.all
    }

    pub fn may_read(&self, tag: &str) -> bool {
        self.all
            || self.names.contains(tag)
            || self.prefixes.iter().any(|p| tag.starts_with(p.as_str()))
            || self
                .comm_prefixes
                .iter()
                .any(|p| tag.starts_with(p.as_str()))
    }
}
