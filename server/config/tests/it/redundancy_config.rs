//! `[redundancy]` and `[server] site`: a good pair loads, and each mistake
//! gives its located error.

use std::fs;

use gridscada_config::load_path;

const TAGS: &str = "[[device]]\nname = \"D1\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:1502\"\n\n[[tag]]\nname = \"A.Volts\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\n";

const PG: &str = "[storage]\nurl = \"postgres://scada@db.example/gridscada\"\n";

const PAIR: &str = "[redundancy]\nname = \"a\"\n[[redundancy.server]]\nname = \"a\"\nurl = \"http://10.0.0.1:8080\"\n[[redundancy.server]]\nname = \"b\"\nurl = \"http://10.0.0.2:8080\"\n";

fn load(main: &str) -> Result<gridscada_config::Plant, Vec<String>> {
    let dir = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("gridscada.toml"), main).unwrap();
    fs::write(dir.path().join("tags.toml"), TAGS).unwrap();
    let prefix = dir.path().display().to_string();
    load_path(dir.path()).map_err(|diags| {
        diags
            .iter()
            .map(|d| d.to_string().replace(&prefix, "DIR"))
            .collect()
    })
}

fn main_file(rest: &str) -> String {
    format!("tag_files = [\"tags.toml\"]\n{rest}")
}

#[test]
fn a_pair_on_postgres_loads_with_the_default_timing() {
    let plant = load(&main_file(&format!(
        "[server]\nsite = \"north-1\"\n{PG}{PAIR}"
    )))
    .unwrap();
    assert_eq!(plant.server.site(), "north-1");
    let r = plant.redundancy.unwrap();
    assert_eq!(r.name.get_ref(), "a");
    assert_eq!(r.url_of("b"), Some("http://10.0.0.2:8080"));
    assert_eq!(r.lease().as_secs_f64(), 3.0);
    assert_eq!(r.takeover().as_secs_f64(), 5.0);
}

#[test]
fn the_site_defaults_to_main() {
    let plant = load(&main_file("")).unwrap();
    assert_eq!(plant.server.site(), "main");
}

#[test]
fn a_pair_on_sqlite_is_refused() {
    let got = load(&main_file(PAIR)).unwrap_err();
    assert_eq!(got.len(), 1, "{got:?}");
    assert!(
        got[0].contains("[redundancy] needs the servers of the pair to share one PostgreSQL database; [storage] url is SQLite"),
        "{got:?}"
    );
}

#[test]
fn each_mistake_is_located() {
    let main = main_file(&format!(
        "[server]\nsite = \"north 1\"\n{PG}[redundancy]\nname = \"c\"\nlease_s = 2.0\nrenew_s = 1.0\ntakeover_s = 2.5\n[[redundancy.server]]\nname = \"a\"\nurl = \"10.0.0.1:8080\"\n[[redundancy.server]]\nname = \"a\"\nurl = \"http://10.0.0.2:8080\"\n"
    ));
    let got = load(&main).unwrap_err();
    let expected = [
        "DIR/gridscada.toml:3:8: error: [server] site: 'north 1' must be 1 to 64 letters, digits, '-' or '_'",
        "DIR/gridscada.toml:7:8: error: [redundancy] name: 'c' is not one of the [[redundancy.server]] names (a, a)",
        "DIR/gridscada.toml:9:11: error: [redundancy] renew_s: 1 s leaves no room for a failed renewal; it must be at most half of lease_s - margin_s (0.750 s)",
        "DIR/gridscada.toml:10:14: error: [redundancy] takeover_s: 2.5 s is shorter than the worst takeover, lease_s + renew_s = 3 s",
        "DIR/gridscada.toml:13:7: error: [[redundancy.server]] url: '10.0.0.1:8080' must be the HMI's address, like http://10.0.0.2:8080",
        "DIR/gridscada.toml:15:8: error: [[redundancy.server]] name: duplicate server 'a' (first at DIR/gridscada.toml:12:8)",
    ];
    assert_eq!(got, expected, "\ngot:\n{}\n", got.join("\n"));
}
