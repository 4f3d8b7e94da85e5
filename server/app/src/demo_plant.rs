//! The demo plant's configuration, embedded in the binary so that
//! `gridscada demo` runs from any folder with nothing else on disk.

use std::io;
use std::path::Path;

use gridscada_config::{Diagnostic, Plant};

/// The files of `tags/`, by name.
const FILES: &[(&str, &str)] = &[
    (
        "gridscada.toml",
        include_str!("../../../tags/gridscada.toml"),
    ),
    (
        "substation-ss1.toml",
        include_str!("../../../tags/substation-ss1.toml"),
    ),
    (
        "substation-css1.toml",
        include_str!("../../../tags/substation-css1.toml"),
    ),
    (
        "microgrid.toml",
        include_str!("../../../tags/microgrid.toml"),
    ),
    ("mv-ring.toml", include_str!("../../../tags/mv-ring.toml")),
];

/// Loads and checks the embedded demo plant.
pub fn load() -> Result<Plant, Vec<Diagnostic>> {
    let read = |p: &Path| -> io::Result<String> {
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        FILES
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, text)| text.to_string())
            .ok_or_else(|| io::Error::from(io::ErrorKind::NotFound))
    };
    gridscada_config::load_with(Path::new("<embedded>/tags/gridscada.toml"), &read)
}
