//! Broken configurations, each with the located error it must produce.
//! The messages are what an engineer reads, so they are asserted as text.

use std::fs;

use gridscada_config::load_path;

const MAIN: &str = "tag_files = [\"tags.toml\"]\n";

const DEVICE: &str = r#"[[device]]
name = "D1"
protocol = "tcp"
address = "127.0.0.1:1502"
"#;

/// Writes `main` and `tags` to a temp folder, loads it, and returns the
/// diagnostics with the folder replaced by `DIR`.
fn problems(main: &str, tags: &str) -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("gridscada.toml"), main).unwrap();
    fs::write(dir.path().join("tags.toml"), tags).unwrap();
    problems_in(dir.path())
}

/// Loads the plant in `dir`; the diagnostics with the folder replaced by `DIR`.
fn problems_in(dir: &std::path::Path) -> Vec<String> {
    let prefix = dir.display().to_string();
    match load_path(dir) {
        Ok(_) => vec![],
        Err(diags) => diags
            .iter()
            .map(|d| d.to_string().replace(&prefix, "DIR"))
            .collect(),
    }
}

fn assert_problems(main: &str, tags: &str, expected: &[&str]) {
    let got = problems(main, tags);
    assert_eq!(got, expected, "\ngot:\n{}\n", got.join("\n"));
}

#[test]
fn a_valid_plant_loads() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.Volts\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\n"
    );
    assert_eq!(problems(MAIN, &tags), Vec::<String>::new());
}

#[test]
fn toml_syntax_error() {
    assert_problems(
        MAIN,
        "[[device]]\nname = \"D1\nprotocol = \"tcp\"\n",
        &["DIR/tags.toml:2:11: error: TOML syntax error: invalid basic string, expected `\"`"],
    );
}

#[test]
fn unknown_field_is_located() {
    let tags = "[[device]]\nname = \"D1\"\nprotocol = \"tcp\"\nadress = \"127.0.0.1:502\"\n";
    let got = problems(MAIN, tags);
    assert_eq!(got.len(), 1, "{got:?}");
    assert!(
        got[0].starts_with(
            "DIR/tags.toml:4:1: error: device 'D1': unknown field `adress`, expected one of `name`"
        ),
        "{got:?}"
    );
}

#[test]
fn unknown_key_in_main_file() {
    let main = "tag_files = [\"tags.toml\"]\nhttp = \"0.0.0.0:80\"\n";
    assert_problems(
        main,
        DEVICE,
        &["DIR/gridscada.toml:2:1: error: unknown key 'http' in the main file; expected one of tag_files, server, storage, panel, microgrid, mqtt, opcua, iec104_server, redundancy, notify, suppression, reports, network, hmi"],
    );
}

#[test]
fn missing_tag_file() {
    let main = "tag_files = [\"tags.toml\", \"nope.toml\"]\n";
    assert_problems(
        main,
        DEVICE,
        &["DIR/gridscada.toml:1:27: error: cannot read tag file 'DIR/nope.toml': no such file"],
    );
}

#[test]
fn duplicate_names() {
    let tags = format!(
        "{DEVICE}\n{DEVICE}\n[[tag]]\nname = \"A.B\"\ndevice = \"D1\"\nkind = \"coil\"\naddress = 0\n\n[[tag]]\nname = \"A.B\"\ndevice = \"D1\"\nkind = \"coil\"\naddress = 1\n"
    );
    assert_problems(
        MAIN,
        &tags,
        &[
            "DIR/tags.toml:7:8: error: duplicate device name 'D1' (first defined at DIR/tags.toml:2:8)",
            "DIR/tags.toml:18:8: error: duplicate tag name 'A.B' (first defined at DIR/tags.toml:12:8)",
        ],
    );
}

#[test]
fn unknown_device() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.B\"\ndevice = \"D7\"\nkind = \"coil\"\naddress = 0\n"
    );
    assert_problems(
        MAIN,
        &tags,
        &["DIR/tags.toml:8:10: error: tag 'A.B': unknown device 'D7'"],
    );
}

#[test]
fn overlapping_registers() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.P\"\ndevice = \"D1\"\nkind = \"holding_register\"\naddress = 10\ntype = \"f64\"\n\n[[tag]]\nname = \"A.Q\"\ndevice = \"D1\"\nkind = \"holding_register\"\naddress = 13\n"
    );
    assert_problems(
        MAIN,
        &tags,
        &["DIR/tags.toml:17:11: error: tag 'A.Q': holding_register 13 on device 'D1' overlaps tag 'A.P' (at DIR/tags.toml:10:11)"],
    );
}

#[test]
fn bits_of_one_register_do_not_overlap_but_the_same_bit_does() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.B0\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 5\nbit = 0\n\n[[tag]]\nname = \"A.B1\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 5\nbit = 1\n\n[[tag]]\nname = \"A.B1again\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 5\nbit = 1\n"
    );
    assert_problems(
        MAIN,
        &tags,
        &["DIR/tags.toml:24:11: error: tag 'A.B1again': input_register 5 on device 'D1' overlaps tag 'A.B1' (at DIR/tags.toml:17:11)"],
    );
}

#[test]
fn out_of_range_register() {
    let tags = format!("{DEVICE}\n[[tag]]\nname = \"A.E\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 65535\ntype = \"u32\"\n");
    assert_problems(
        MAIN,
        &tags,
        &["DIR/tags.toml:10:11: error: tag 'A.E': address 65535 with 2 registers runs past 65535"],
    );
}

#[test]
fn type_and_width_mismatches() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.C\"\ndevice = \"D1\"\nkind = \"coil\"\naddress = 0\ntype = \"f32\"\n\n[[tag]]\nname = \"A.S\"\ndevice = \"D1\"\nkind = \"holding_register\"\naddress = 10\ntype = \"string\"\n\n[[tag]]\nname = \"A.Bit\"\ndevice = \"D1\"\nkind = \"holding_register\"\naddress = 20\nbit = 16\n"
    );
    assert_problems(
        MAIN,
        &tags,
        &[
            "DIR/tags.toml:11:8: error: tag 'A.C': a coil holds one bit, so its type must be bool, not f32",
            "DIR/tags.toml:14:8: error: tag 'A.S': a string tag needs length (registers, two characters each)",
            "DIR/tags.toml:25:7: error: tag 'A.Bit': bit 16 is outside 0..=15",
        ],
    );
}

#[test]
fn limit_ordering() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.V\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\n[tag.alarm]\nlolo = {{ limit = 190.0 }}\nlo = {{ limit = 207.0 }}\nhi = {{ limit = 200.0 }}\nhihi = {{ limit = 265.0 }}\n"
    );
    assert_problems(
        MAIN,
        &tags,
        &["DIR/tags.toml:15:16: error: tag 'A.V': alarm limits must be ordered LoLo < Lo < Hi < HiHi, but lo = 207 is not below hi = 200"],
    );
}

#[test]
fn writable_without_role_and_read_only_tables() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.Cmd\"\ndevice = \"D1\"\nkind = \"coil\"\naddress = 0\nwritable = true\n\n[[tag]]\nname = \"A.Status\"\ndevice = \"D1\"\nkind = \"discrete_input\"\naddress = 0\nwritable = true\nwrite_role = \"operator\"\n"
    );
    assert_problems(
        MAIN,
        &tags,
        &[
            "DIR/tags.toml:11:12: error: tag 'A.Cmd': writable tags need write_role (operator, supervisor or administrator)",
            "DIR/tags.toml:18:12: error: tag 'A.Status': a discrete_input is read-only in Modbus; only coils and holding registers can be writable",
        ],
    );
}

#[test]
fn a_broken_device_is_reported_once_not_per_tag() {
    let mut tags = String::from(
        "[[device]]\nname = \"P7\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:1502\"\nscan_rate_ms = 500\n",
    );
    for i in 0..42 {
        tags += &format!(
            "\n[[tag]]\nname = \"P7.R{i}\"\ndevice = \"P7\"\nkind = \"holding_register\"\naddress = {i}\n"
        );
    }
    let got = problems(MAIN, &tags);
    assert_eq!(got.len(), 1, "{got:#?}");
    assert!(got[0].contains("scan_rate_ms"), "{got:#?}");
    // A tag naming a device that exists nowhere is still an error.
    let got = problems(
        MAIN,
        &format!(
            "{tags}\n[[tag]]\nname = \"Q.R\"\ndevice = \"Q9\"\nkind = \"coil\"\naddress = 0\n"
        ),
    );
    assert!(
        got.iter().any(|e| e.contains("unknown device 'Q9'")),
        "{got:#?}"
    );
    assert_eq!(got.len(), 2, "{got:#?}");
}

#[test]
fn write_limits_are_checked() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.Set\"\ndevice = \"D1\"\nkind = \"holding_register\"\naddress = 0\ntype = \"f32\"\nwritable = true\nwrite_role = \"operator\"\nmin = 10.0\nmax = 5.0\n\n[[tag]]\nname = \"A.Volts\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\nmax = 5.0\n\n[[tag]]\nname = \"A.Cmd\"\ndevice = \"D1\"\nkind = \"coil\"\naddress = 0\nwritable = true\nwrite_role = \"operator\"\nmin = 0.0\n"
    );
    assert_problems(
        MAIN,
        &tags,
        &[
            "DIR/tags.toml:15:7: error: tag 'A.Set': max 5 is below min 10",
            "DIR/tags.toml:23:7: error: tag 'A.Volts': min and max are write limits; the tag is not writable",
            "DIR/tags.toml:32:7: error: tag 'A.Cmd': min and max apply to numeric tags only",
        ],
    );
    // A valid pair loads, and the plant reports it.
    let dir = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("gridscada.toml"), MAIN).unwrap();
    fs::write(
        dir.path().join("tags.toml"),
        format!("{DEVICE}\n[[tag]]\nname = \"A.Set\"\ndevice = \"D1\"\nkind = \"holding_register\"\naddress = 0\ntype = \"f32\"\nwritable = true\nwrite_role = \"operator\"\nmin = -5.0\nmax = 50.0\n"),
    )
    .unwrap();
    let plant = load_path(dir.path()).unwrap();
    assert_eq!(plant.write_limits("A.Set"), (Some(-5.0), Some(50.0)));
    assert_eq!(plant.write_limits("Other"), (None, None));
}

#[test]
fn decimals_are_checked() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.Volts\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\ndecimals = -1\n\n[[tag]]\nname = \"A.Cmd\"\ndevice = \"D1\"\nkind = \"coil\"\naddress = 0\ndecimals = 1\n"
    );
    assert_problems(
        &format!("{MAIN}\n[hmi]\ndecimals = 9\n"),
        &tags,
        &[
            "DIR/gridscada.toml:4:12: error: [hmi] decimals: 9 must be 0 to 6",
            "DIR/tags.toml:12:12: error: tag 'A.Volts': decimals -1 must be 0 to 6",
            "DIR/tags.toml:19:12: error: tag 'A.Cmd': decimals apply to numeric tags only",
        ],
    );
    // A date format outside the set is named where it is.
    let got = problems(&format!("{MAIN}[hmi]\ndate_format = \"D.M.YY\"\n"), &tags);
    assert!(
        got.iter()
            .any(|e| e.starts_with("DIR/gridscada.toml:3:15: error: [hmi]")
                && e.contains("unknown variant `D.M.YY`")
                && e.contains("`DD.MM.YYYY`")),
        "{got:#?}"
    );
}

#[test]
fn decimals_resolve_to_the_tag_s_own_else_the_plant_s() {
    let dir = tempfile::tempdir().unwrap();
    fs::write(
        dir.path().join("gridscada.toml"),
        format!("{MAIN}[hmi]\ndecimals = 2\ndate_format = \"DD.MM.YYYY\"\n"),
    )
    .unwrap();
    fs::write(
        dir.path().join("tags.toml"),
        format!("{DEVICE}\n[[tag]]\nname = \"A.Hz\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\ndecimals = 3\n\n[[tag]]\nname = \"A.Volts\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 2\ntype = \"f32\"\n\n[[tag]]\nname = \"A.Count\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 4\n\n[[tag]]\nname = \"A.Closed\"\ndevice = \"D1\"\nkind = \"coil\"\naddress = 0\n"),
    )
    .unwrap();
    let plant = load_path(dir.path()).unwrap();
    let shown = |name: &str| {
        let t = plant.tag(name).unwrap();
        plant.hmi.decimals_for(t.value_kind(), t.decimals())
    };
    assert_eq!(shown("A.Hz"), Some(3), "the tag's own");
    assert_eq!(shown("A.Volts"), Some(2), "[hmi] decimals");
    assert_eq!(shown("A.Count"), Some(0), "an integer has none");
    assert_eq!(shown("A.Closed"), None, "a bool is not a number");
    assert_eq!(plant.hmi.date_format.get_ref().pattern(), "DD.MM.YYYY");
    // Without [hmi]: one decimal, ISO dates.
    let plant =
        load_path(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags")).unwrap();
    assert_eq!(plant.hmi.decimals(), 1);
    assert_eq!(plant.hmi.date_format.get_ref().pattern(), "YYYY-MM-DD");
}

#[test]
fn microgrid_setpoints_are_limited_by_their_ratings() {
    let plant =
        load_path(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags")).unwrap();
    assert_eq!(
        plant.write_limits("MG.PV1.Setpoint_kW"),
        (Some(0.0), Some(100.0))
    );
    assert_eq!(
        plant.write_limits("MG.BESS1.Setpoint_kW"),
        (Some(-50.0), Some(60.0))
    );
    assert_eq!(
        plant.write_limits("MG.DG1.Setpoint_kW"),
        (Some(0.0), Some(150.0))
    );
}

#[test]
fn bad_enum_value_names_the_choices() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.B\"\ndevice = \"D1\"\nkind = \"register\"\naddress = 0\n"
    );
    let got = problems(MAIN, &tags);
    assert_eq!(got.len(), 1, "{got:?}");
    assert!(
        got[0].starts_with("DIR/tags.toml:9:8: error: tag 'A.B': unknown variant `register`, expected one of `coil`, `discrete_input`, `input_register`, `holding_register`"),
        "{got:?}"
    );
}

#[test]
fn every_problem_is_reported_not_just_the_first() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.B\"\ndevice = \"D9\"\nkind = \"coil\"\naddress = 0\n\n[[tag]]\nname = \"bad name\"\ndevice = \"D1\"\nkind = \"coil\"\naddress = 1\n\n[[tag]]\nname = \"A.C\"\ndevice = \"D1\"\nkind = \"coil\"\naddress = 2\nbogus = 1\n"
    );
    let got = problems(MAIN, &tags);
    assert_eq!(got.len(), 3, "{got:?}");
}

#[test]
fn panel_needs_its_io_tags() {
    let main = "tag_files = [\"tags.toml\"]\n\n[[panel]]\nid = \"p1\"\nname = \"Panel\"\nkind = \"service\"\nprefix = \"P1\"\nzones = 1\n";
    let got = problems(main, DEVICE);
    assert_eq!(got.len(), 6, "{got:?}");
    assert_eq!(got[0], "DIR/gridscada.toml:7:10: error: panel 'p1': needs tag 'P1.ELCB.Closed', which no tag file defines");
}

#[test]
fn server_address_and_storage_url() {
    let main = "tag_files = [\"tags.toml\"]\n[server]\nhttp = \"localhost\"\n[storage]\nurl = \"mysql://x\"\n";
    assert_problems(
        main,
        DEVICE,
        &[
            "DIR/gridscada.toml:3:8: error: [server] http: 'localhost' is not an address like 127.0.0.1:8080",
            "DIR/gridscada.toml:5:7: error: [storage] url: 'mysql://x' must start with sqlite:, postgres:// or postgresql://",
        ],
    );
}

#[test]
fn the_demo_plant_is_valid() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags");
    let plant = load_path(&dir).unwrap_or_else(|d| panic!("{d:?}"));
    assert_eq!(plant.panels.len(), 2);
    assert!(plant.microgrid.is_some());
}

#[test]
fn the_telecontrol_test_plant_is_valid() {
    let dir =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/plants/telecontrol");
    let plant = load_path(&dir).unwrap_or_else(|d| panic!("{d:?}"));
    // Panel FX over IEC 104, panel FY over DNP3.
    assert_eq!(plant.panels.len(), 2);
}

#[test]
fn panel_dwell_against_a_dnp3_outstation_depends_on_how_events_come() {
    let main = "tag_files = [\"tags.toml\"]\n\n[[panel]]\nid = \"p1\"\nname = \"Panel\"\nkind = \"service\"\nprefix = \"P1\"\nzones = 1\ndwell_s = 1.0\n";
    let mut tags = String::from(
        "[[device]]\nname = \"P1.OS\"\nprotocol = \"dnp3\"\naddress = \"127.0.0.1:20000\"\n\n\
         [device.dnp3]\nunsolicited = false\nevent_poll_period_s = 2\nresponse_timeout_ms = 500\n",
    );
    for (i, (name, writable)) in [
        ("P1.ELCB.Closed", false),
        ("P1.MCCB.Closed", false),
        ("P1.Zone1.Closed", false),
        ("P1.ELCB.Reset", true),
        ("P1.MCCB.Cmd", true),
        ("P1.Zone1.Cmd", true),
    ]
    .into_iter()
    .enumerate()
    {
        let command = if writable { ", command = \"crob\"" } else { "" };
        let write = if writable {
            "writable = true\nwrite_role = \"operator\"\n"
        } else {
            ""
        };
        tags.push_str(&format!(
            "\n[[tag]]\nname = \"{name}\"\ndevice = \"P1.OS\"\ntype = \"bool\"\n{write}dnp3 = {{ point = \"binary_input\", index = {i}{command} }}\n"
        ));
    }
    assert_problems(
        main,
        &tags,
        &["DIR/gridscada.toml:9:11: error: panel 'p1': dwell_s = 1 s is too short to attribute a trip: the ELCB status (P1.OS) is polled for events every 2000 ms with a 500 ms timeout; dwell_s must exceed 2.5 s"],
    );
    // With unsolicited responses the outstation reports the trip at once.
    let unsolicited = tags.replace("unsolicited = false", "unsolicited = true");
    assert_problems(main, &unsolicited, &[]);
}

#[test]
fn panel_dwell_shorter_than_the_elcb_status_latency() {
    let main = "tag_files = [\"tags.toml\"]\n\n[[panel]]\nid = \"ss1\"\nname = \"Panel\"\nkind = \"service\"\nprefix = \"SS1\"\nzones = 1\ndwell_s = 0.3\n";
    let tags = r#"[[device]]
name = "SS1.IO1"
protocol = "tcp"
address = "127.0.0.1:1502"
scan_ms = 200
timeout_ms = 150

[[tag]]
name = "SS1.ELCB.Closed"
device = "SS1.IO1"
kind = "discrete_input"
address = 0

[[tag]]
name = "SS1.MCCB.Closed"
device = "SS1.IO1"
kind = "discrete_input"
address = 1

[[tag]]
name = "SS1.Zone1.Closed"
device = "SS1.IO1"
kind = "discrete_input"
address = 2

[[tag]]
name = "SS1.ELCB.Reset"
device = "SS1.IO1"
kind = "coil"
address = 0
writable = true
write_role = "operator"

[[tag]]
name = "SS1.MCCB.Cmd"
device = "SS1.IO1"
kind = "coil"
address = 1
writable = true
write_role = "operator"

[[tag]]
name = "SS1.Zone1.Cmd"
device = "SS1.IO1"
kind = "coil"
address = 2
writable = true
write_role = "operator"
"#;
    assert_problems(
        main,
        tags,
        &["DIR/gridscada.toml:9:11: error: panel 'ss1': dwell_s = 0.3 s is too short to attribute a trip: the ELCB status (SS1.IO1) is read every 200 ms with a 150 ms timeout; dwell_s must exceed 0.35 s"],
    );
    // Longer than scan + timeout: accepted.
    let ok = main.replace("dwell_s = 0.3", "dwell_s = 0.4");
    assert_problems(&ok, tags, &[]);
}

/// The demo plant with its main file edited by `edit`: the problems.
fn demo_plant_with(edit: impl Fn(String) -> String) -> Vec<String> {
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags");
    let dir = tempfile::tempdir().unwrap();
    for f in fs::read_dir(&src).unwrap() {
        let f = f.unwrap().path();
        fs::copy(&f, dir.path().join(f.file_name().unwrap())).unwrap();
    }
    let main = dir.path().join("gridscada.toml");
    fs::write(&main, edit(fs::read_to_string(&main).unwrap())).unwrap();
    problems_in(dir.path())
}

#[test]
fn the_demo_plant_looks_ahead_with_forecasts() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags");
    let plant = load_path(&dir).unwrap_or_else(|d| panic!("{d:?}"));
    let mg = plant.microgrid.unwrap();
    let h = mg.horizon.expect("the demo plant has a horizon");
    assert_eq!(*h.periods.get_ref(), 16.0);
    // A plan is used in the dispatch period it is made in.
    assert_eq!(h.adopt_after_s(), 0.0);
    // Integers and floats both read as numbers.
    assert_eq!(h.demand_forecast_kw.unwrap().get_ref()[0], (0.0, 61.0));
    assert!(mg.units[0].forecast_kw.is_some());
}

#[test]
fn horizon_settings_and_forecast_curves_are_checked() {
    let got = demo_plant_with(|s| {
        s.replace("periods = 16\n", "periods = 2.5\n")
            .replace("resolve_s = 300.0", "resolve_s = 1.0")
            .replace("[0, 61], [2, 60]", "[0, 61], [0, 60]")
            .replace("[12, 95]", "[12, 195]")
            .replace("[18, 0],\n]", "[24, 0],\n]")
    });
    let want = [
        "periods must be a whole number from 1 to 672",
        "resolve_s (1 s) is shorter than dispatch_period_s (5 s)",
        "demand_forecast_kw point 2 [0, 60]: hour 0 is given twice",
        "microgrid unit 'pv1': forecast_kw point 7 [12, 195]: the value exceeds rated_kw 100",
        "microgrid unit 'pv1': forecast_kw point 13 [24, 0]: the hour must be in [0, 24)",
    ];
    assert_eq!(got.len(), want.len(), "{got:#?}");
    for w in want {
        assert!(
            got.iter()
                .any(|g| g.starts_with("DIR/gridscada.toml:") && g.contains(w)),
            "no '{w}' in {got:#?}"
        );
    }
    // A plan must be adopted before the next one is due.
    let got = demo_plant_with(|s| {
        s.replace(
            "resolve_s = 300.0",
            "resolve_s = 300.0\nadopt_after_s = 300",
        )
    });
    assert!(
        got.len() == 1
            && got[0].starts_with("DIR/gridscada.toml:")
            && got[0].contains(
                "adopt_after_s (300 s) must be 0 or more and shorter than resolve_s (300 s)"
            ),
        "{got:#?}"
    );
    let got = demo_plant_with(|s| {
        s.replace("resolve_s = 300.0", "resolve_s = 300.0\nadopt_after_s = -1")
    });
    assert!(
        got.len() == 1 && got[0].contains("adopt_after_s (-1 s)"),
        "{got:#?}"
    );
    // A forecast on a storage unit is refused by name.
    let got = demo_plant_with(|s| {
        s.replace(
            "cycle_cost_per_kwh = 0.02\n",
            "cycle_cost_per_kwh = 0.02\nforecast_kw = [[0, 1]]\n",
        )
    });
    assert!(
        got.len() == 1 && got[0].contains("forecast_kw is for PV and wind units only"),
        "{got:#?}"
    );
}

#[test]
fn device_clocks_are_checked() {
    let d2 = "[[device]]\nname = \"D2\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:1503\"\ntime_tag = \"Nope\"\n";
    let tag = |name: &str, dev: &str, addr: u32, extra: &str| {
        format!("[[tag]]\nname = \"{name}\"\ndevice = \"{dev}\"\nkind = \"holding_register\"\naddress = {addr}\n{extra}\n")
    };
    let tags = [
        DEVICE.to_string(),
        d2.to_string(),
        tag(
            "D1.Clock",
            "D1",
            0,
            "type = \"datetime\"\nwritable = true\nwrite_role = \"operator\"",
        ),
        tag("D1.Flag", "D1", 10, "type = \"bool\"\nbit = 0"),
        tag("D1.A", "D1", 11, "time_tag = \"D1.Clock\"\nscan_ms = 500"),
        tag("D1.B", "D1", 12, "time_tag = \"D1.Flag\""),
        tag("D2.C", "D2", 0, "time_tag = \"D1.Clock\""),
        tag("D2.D", "D2", 1, "time_tag = \"receive\""),
    ]
    .concat();
    assert_problems(
        MAIN,
        &tags,
        &[
            "DIR/tags.toml:9:12: error: device 'D2': time_tag 'Nope' is not a tag",
            "DIR/tags.toml:16:12: error: tag 'D1.Clock': a datetime is a device clock, read-only; it cannot be writable",
            "DIR/tags.toml:30:12: error: tag 'D1.A': scanned every 500 ms but its device clock 'D1.Clock' every 1000 ms; a clock stamps only the tags read in its own scan (give them the same scan_ms, or time_tag = \"receive\")",
            "DIR/tags.toml:37:12: error: tag 'D1.B': time_tag 'D1.Flag' is a bool; a device clock is a datetime or a number of Unix seconds",
            "DIR/tags.toml:43:12: error: tag 'D2.C': time_tag 'D1.Clock' is a tag of device 'D1', not of 'D2'",
        ],
    );
}

#[test]
fn comm_alarm_delays_are_checked() {
    let tags = format!("{DEVICE}\n[device.comm_alarm]\non_delay_s = -1.0\noff_delay_s = 4000.0\n");
    assert_problems(
        MAIN,
        &tags,
        &[
            "DIR/tags.toml:7:14: error: device 'D1': comm_alarm on_delay_s must be 0 to 3600 seconds",
            "DIR/tags.toml:8:15: error: device 'D1': comm_alarm off_delay_s must be 0 to 3600 seconds",
        ],
    );
}

#[test]
fn session_policy_is_checked() {
    let main = "tag_files = [\"tags.toml\"]\n[server.sessions]\nidle_minutes = { operator = -1.0, display = 0.0 }\nabsolute_hours = 1000.0\nwarn_s = 7200\nstore_wait_ms = 0\n";
    let tags = format!("{DEVICE}\n[[tag]]\nname = \"A.V\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\n");
    let got = problems(main, &tags);
    assert_eq!(got.len(), 4, "{got:?}");
    assert!(
        got[0].contains("idle_minutes.operator: -1 must be 0 (never) to 10080"),
        "{got:?}"
    );
    assert!(
        got[1].contains("absolute_hours: 1000 must be 0 (never) to 720"),
        "{got:?}"
    );
    assert!(got[2].contains("warn_s: at most 3600 seconds"), "{got:?}");
    assert!(
        got[3].contains("gridscada.toml:6:17: error: [server.sessions] store_wait_ms: 0 must be 10 to 10000 milliseconds"),
        "{got:?}"
    );
    assert!(
        got.iter().all(|g| g.starts_with("DIR/gridscada.toml:")),
        "{got:?}"
    );
}

#[test]
fn reverse_proxy_settings_are_checked_where_they_stand() {
    let main = format!(
        "{MAIN}[server]\npublic_origin = \"https://scada.example.com/scada\"\ntrusted_proxies = [\"127.0.0.1/32\", \"10.0.0.1/8\", \"proxy.lan\"]\nbase_path = \"scada/\"\nforwarded_header = \"x-real-ip\"\n"
    );
    assert_problems(
        &main,
        DEVICE,
        &[
            "DIR/gridscada.toml:3:17: error: [server] public_origin: 'https://scada.example.com/scada': an origin is scheme, host and port only ('/' found); a sub-path goes in [server] base_path",
            "DIR/gridscada.toml:4:36: error: [server] trusted_proxies: '10.0.0.1/8' has address bits set past the /8 (did you mean 10.0.0.0/8?) (write a block like 10.0.0.0/8 or ::1/128)",
            "DIR/gridscada.toml:4:50: error: [server] trusted_proxies: 'proxy.lan' is not an IP address (write a block like 10.0.0.0/8 or ::1/128)",
            "DIR/gridscada.toml:5:13: error: [server] base_path: 'scada/' must start with / (like /scada)",
            "DIR/gridscada.toml:6:20: error: [server] forwarded_header: 'x-real-ip' is not a forwarding header; write \"x-forwarded-for\" or \"forwarded\", the one your proxy sets",
        ],
    );
}

#[test]
fn good_reverse_proxy_settings_load_in_normal_form() {
    let dir = tempfile::tempdir().unwrap();
    fs::write(
        dir.path().join("gridscada.toml"),
        format!("{MAIN}[server]\npublic_origin = \"https://SCADA.example.com:443\"\ntrusted_proxies = [\"127.0.0.1/32\", \"::1/128\", \"10.0.0.0/8\"]\nbase_path = \"/scada/\"\nforwarded_header = \"Forwarded\"\n"),
    )
    .unwrap();
    fs::write(dir.path().join("tags.toml"), DEVICE).unwrap();
    let plant = load_path(dir.path()).unwrap();
    assert_eq!(
        plant.server.forwarded_header(),
        gridscada_config::ForwardedHeader::Forwarded
    );
    assert_eq!(
        plant.server.public_origin().as_deref(),
        Some("https://scada.example.com")
    );
    assert_eq!(plant.server.base_path(), "/scada");
    let proxies: Vec<String> = plant
        .server
        .trusted_proxies()
        .iter()
        .map(|c| c.to_string())
        .collect();
    assert_eq!(proxies, ["127.0.0.1/32", "::1/128", "10.0.0.0/8"]);
}

#[test]
fn audit_retention_is_checked_and_located() {
    let main = "tag_files = [\"tags.toml\"]\n[storage.retention]\nevents_days = 40000\ndispatch_days = 0\n";
    let tags = format!("{DEVICE}\n[[tag]]\nname = \"A.V\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\n");
    assert_eq!(
        problems(main, &tags),
        ["DIR/gridscada.toml:3:15: error: [storage.retention] events_days: 40000 days is more than 100 years; 0 keeps for ever"]
    );
    let main = "tag_files = [\"tags.toml\"]\n[storage.retention]\nevent_days = 30\n";
    let got = problems(main, &tags);
    assert!(got[0].contains("event_days"), "{got:?}");
}

#[test]
fn mqtt_edge_settings_are_checked_where_they_are() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.Volts\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\n\n[[tag]]\nname = \"A.Cmd\"\ndevice = \"D1\"\nkind = \"coil\"\naddress = 0\nwritable = true\nwrite_role = \"operator\"\n"
    );
    let main = format!(
        "{MAIN}[mqtt]\nbroker = \"tcp://broker:1883\"\ngroup = \"a/b\"\npassword = \"x\"\nkeep_alive_s = 0\n\n[mqtt.edge]\nnode = \"n#1\"\ndeadband = -1.0\nbatch_ms = 5\ncommands = [\"A.Volts\", \"Nope.*\", \"A.Cmd\", \"A.*\"]\nprimary_host_id = \"scada/1\"\n"
    );
    assert_problems(
        &main,
        &tags,
        &[
            "DIR/gridscada.toml:3:10: error: [mqtt] broker: 'tcp://broker:1883' must start with mqtt:// or mqtts://, like mqtt://broker.example:1883",
            "DIR/gridscada.toml:4:9: error: [mqtt] group: 'a/b' must be a topic level: not empty, without '/', '+' or '#'",
            "DIR/gridscada.toml:5:12: error: [mqtt] password: given without a username",
            "DIR/gridscada.toml:6:16: error: [mqtt] keep_alive_s: 0 must be 1 to 3600 seconds",
            "DIR/gridscada.toml:9:8: error: [mqtt.edge] node: 'n#1' must be a topic level: not empty, without '/', '+' or '#'",
            "DIR/gridscada.toml:10:12: error: [mqtt.edge] deadband: -1 must be 0 or more",
            "DIR/gridscada.toml:11:12: error: [mqtt.edge] batch_ms: 5 must be 10 to 60000",
            "DIR/gridscada.toml:12:13: error: [mqtt.edge] commands: tag 'A.Volts' is not writable",
            "DIR/gridscada.toml:12:24: error: [mqtt.edge] commands: 'Nope.*' names no tag of the tag files",
            "DIR/gridscada.toml:13:19: error: [mqtt.edge] primary_host_id: 'scada/1' must be a topic level: not empty, without '/', '+' or '#'",
        ],
    );
}

/// `[server.access.GROUP] write` (issue 36 #5): checked like `[mqtt.edge]
/// commands`, each problem where it is written; a group that may write
/// reads back its grants.
#[test]
fn group_write_grants_are_checked_where_they_are() {
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.Volts\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\n\n[[tag]]\nname = \"A.Cmd\"\ndevice = \"D1\"\nkind = \"coil\"\naddress = 0\nwritable = true\nwrite_role = \"operator\"\n"
    );
    let main = format!(
        "{MAIN}[server.access.east]\nwrite = [\"A.Volts\", \"Nope.*\", \"A.*\", \"A*.*\"]\n[server.access.\" west\"]\nwrite = [\"A.Cmd\"]\n"
    );
    assert_problems(
        &main,
        &tags,
        &[
            "DIR/gridscada.toml:3:10: error: [server.access.east] write: tag 'A.Volts' is not writable",
            "DIR/gridscada.toml:3:21: error: [server.access.east] write: 'Nope.*' names no tag of the tag files",
            "DIR/gridscada.toml:3:38: error: [server.access.east] write: 'A*.*' must be a tag name or a prefix ending in '*'",
            "DIR/gridscada.toml:4:16: error: [server.access] ' west': a group name needs 1 to 64 printable characters, without spaces at either end",
        ],
    );
    let main = format!(
        "{MAIN}[server.access.east]\nwrite = [\"A.*\"]\n[server.access.unknown]\nwritten = []\n"
    );
    let got = problems(&main, &tags);
    assert!(got[0].contains("written"), "{got:?}");
    let main = format!("{MAIN}[server.access.east]\nwrite = [\"A.*\"]\n");
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("gridscada.toml"), &main).unwrap();
    std::fs::write(dir.path().join("tags.toml"), &tags).unwrap();
    let plant = gridscada_config::load_path(dir.path()).unwrap_or_else(|d| panic!("{d:?}"));
    assert!(plant.server.grants_write("east", "A.Cmd"));
    assert!(!plant.server.grants_write("west", "A.Cmd"));
    assert!(!plant.server.grants_write("east", "B.Cmd"));
}

#[test]
fn mqtts_needs_a_ca_file_and_devices_must_be_topic_levels() {
    let tags =
        "[[device]]\nname = \"gridscada\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:1502\"\n";
    let main = format!(
        "{MAIN}[mqtt]\nbroker = \"mqtts://broker.example:8883\"\ngroup = \"G\"\n[mqtt.edge]\nnode = \"n1\"\n"
    );
    assert_problems(
        &main,
        tags,
        &[
            "DIR/gridscada.toml:3:10: error: [mqtt] broker: an mqtts:// broker needs ca_file, the CA certificate(s) that signed the broker's certificate (PEM)",
            "DIR/tags.toml:2:8: error: device 'gridscada': with [mqtt.edge], this name is taken by the Sparkplug device of the server's own tags",
        ],
    );
}

#[test]
fn opcua_section_is_checked_and_located() {
    let main = "tag_files = [\"tags.toml\"]\n[server]\nhttp = \"127.0.0.1:8080\"\n[opcua]\nlisten = \"0.0.0.0:8080\"\nhost = \"bad host\"\nsecurity = [\"none\", \"none\"]\npki_dir = \" \"\n";
    assert_problems(
        main,
        DEVICE,
        &[
            "DIR/gridscada.toml:5:10: error: [opcua] listen: port 8080 is the HMI's ([server] http); give OPC UA its own (4840 is usual)",
            "DIR/gridscada.toml:6:8: error: [opcua] host: 'bad host' is not a host name or IP address clients can resolve",
            "DIR/gridscada.toml:7:12: error: [opcua] security: 'none' is listed twice",
            "DIR/gridscada.toml:8:11: error: [opcua] pki_dir: must name a folder (relative to the data folder)",
        ],
    );
    let main = "tag_files = [\"tags.toml\"]\n[opcua]\nlisten = \"4840\"\nsecurity = []\n";
    assert_problems(
        main,
        DEVICE,
        &[
            "DIR/gridscada.toml:3:10: error: [opcua] listen: '4840' is not an address like 0.0.0.0:4840",
            "DIR/gridscada.toml:4:12: error: [opcua] security: offer at least one endpoint (\"basic256sha256-sign-encrypt\" is the safe choice)",
        ],
    );
    let main = "tag_files = [\"tags.toml\"]\n[opcua]\nlisten = \"0.0.0.0:4840\"\nsecurity = [\"basic128\"]\n";
    let got = problems(main, DEVICE);
    assert_eq!(got.len(), 1, "{got:?}");
    assert!(
        got[0].starts_with("DIR/gridscada.toml:4:13: error: [opcua]: unknown variant `basic128`, expected one of `none`, `basic256sha256-sign`, `basic256sha256-sign-encrypt`"),
        "{got:?}"
    );
}

#[test]
fn opcua_connection_caps_are_checked_and_located() {
    let main =
        "tag_files = [\"tags.toml\"]\n[opcua]\nlisten = \"0.0.0.0:4840\"\nmax_connections = 0\n";
    assert_problems(
        main,
        DEVICE,
        &[
            "DIR/gridscada.toml:4:19: error: [opcua] max_connections: 0 is out of range; 1 to 10000 open connections",
        ],
    );
    let main = "tag_files = [\"tags.toml\"]\n[opcua]\nlisten = \"0.0.0.0:4840\"\nmax_connections = 16\nmax_connections_per_client = 17\n";
    assert_problems(
        main,
        DEVICE,
        &["DIR/gridscada.toml:5:30: error: [opcua] max_connections_per_client: 17 must be 1 to max_connections (16)"],
    );
}

const STATION: &str = r#"[[device]]
name = "RTU"
protocol = "iec104"
address = "127.0.0.1:2404"
"#;

#[test]
fn an_iec104_plant_loads() {
    let tags = format!(
        "{STATION}\n[device.iec104]\ncommon_address = 7\nredundant_addresses = [\"127.0.0.1:2405\"]\n\n\
         [[tag]]\nname = \"RTU.Q1\"\ndevice = \"RTU\"\ntype = \"bool\"\nwritable = true\nwrite_role = \"operator\"\n\
         iec104 = {{ ioa = 1001, point = \"M_DP\", command = \"C_DC\", command_ioa = 2001, select = true }}\n\n\
         [[tag]]\nname = \"RTU.U\"\ndevice = \"RTU\"\nscale = 0.1\niec104 = {{ ioa = 3001, point = \"M_ME_NB\" }}\n"
    );
    assert_eq!(problems(MAIN, &tags), Vec::<String>::new());
}

#[test]
fn iec104_points_are_checked_against_their_tag_and_device() {
    let tags = format!(
        "{STATION}\n[device.iec104]\nw = 20\n\n\
         [[tag]]\nname = \"RTU.A\"\ndevice = \"RTU\"\ntype = \"f32\"\niec104 = {{ ioa = 5, point = \"M_SP\" }}\n\n\
         [[tag]]\nname = \"RTU.B\"\ndevice = \"RTU\"\niec104 = {{ ioa = 5, point = \"M_DP\", command = \"C_DC\" }}\n\n\
         [[tag]]\nname = \"RTU.C\"\ndevice = \"RTU\"\nkind = \"coil\"\naddress = 3\n\n\
         {DEVICE}\n[[tag]]\nname = \"D.X\"\ndevice = \"D1\"\niec104 = {{ ioa = 9, point = \"M_SP\" }}\n"
    );
    assert_problems(
        MAIN,
        &tags,
        &[
            "DIR/tags.toml:7:5: error: device 'RTU': w = 20 must be 1 to two thirds of k = 12",
            "DIR/tags.toml:12:8: error: tag 'RTU.A': a M_SP point cannot carry a f32 value (use type = \"bool\")",
            "DIR/tags.toml:18:18: error: tag 'RTU.B': monitored information object address 5 of device 'RTU' is used by tag 'RTU.A' too (at DIR/tags.toml:13:18)",
            "DIR/tags.toml:18:47: error: tag 'RTU.B': command C_DC is set on a read-only tag (set writable = true and write_role)",
            "DIR/tags.toml:21:8: error: tag 'RTU.C': a tag of IEC 104 device 'RTU' needs iec104 = { ioa = …, point = \"M_SP\" }",
            "DIR/tags.toml:23:8: error: tag 'RTU.C': kind is a Modbus setting; device 'RTU' speaks IEC 104 (use iec104 = { ioa = …, point = … })",
            "DIR/tags.toml:24:11: error: tag 'RTU.C': address is a Modbus setting; device 'RTU' speaks IEC 104 (use iec104 = { ioa = …, point = … })",
            "DIR/tags.toml:32:8: error: tag 'D.X': a tag of a Modbus device needs kind (coil, discrete_input, input_register or holding_register) and address",
            "DIR/tags.toml:34:18: error: tag 'D.X': iec104 is for tags of protocol = \"iec104\" devices, and device 'D1' is Modbus",
        ],
    );
}

#[test]
fn iec104_server_points_are_checked() {
    let main = "tag_files = [\"tags.toml\"]\n\n[iec104_server]\nlisten = \"0.0.0.0:2404\"\nallowed_clients = [\"10.0.0.300\"]\n\n\
                [[iec104_server.point]]\ntag = \"A.Volts\"\nioa = 7\npoint = \"M_SP\"\n\n\
                [[iec104_server.point]]\ntag = \"A.Volts\"\nioa = 7\npoint = \"M_ME_NC\"\ncommand = \"C_SE_NC\"\n";
    let tags = format!(
        "{DEVICE}\n[[tag]]\nname = \"A.Volts\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\n"
    );
    let got = problems(main, &tags);
    let want = [
        "'10.0.0.300' is not an IP address",
        "a M_SP point cannot carry the tag's f32 values",
        "IOA 7 is already point 'A.Volts'",
        "command C_SE_NC on a tag that is not writable",
    ];
    for w in want {
        assert!(
            got.iter()
                .any(|g| g.contains(w) && g.starts_with("DIR/gridscada.toml:")),
            "{w}\ngot:\n{}",
            got.join("\n")
        );
    }
    assert_eq!(got.len(), want.len(), "{}", got.join("\n"));
}

const OUTSTATION: &str = r#"[[device]]
name = "OS"
protocol = "dnp3"
address = "127.0.0.1:20000"
"#;

#[test]
fn a_dnp3_plant_loads() {
    let tags = format!(
        "{OUTSTATION}\n[device.dnp3]\nmaster_address = 1\noutstation_address = 10\nevent_poll_period_s = 0\ntime_sync = \"none\"\n\n\
         [[tag]]\nname = \"OS.Q1\"\ndevice = \"OS\"\ntype = \"bool\"\nwritable = true\nwrite_role = \"operator\"\n\
         dnp3 = {{ point = \"double_bit\", index = 0, command = \"crob\", command_index = 3, select = true, op = \"trip_close\", on_ms = 500 }}\n\n\
         [[tag]]\nname = \"OS.P\"\ndevice = \"OS\"\nunits = \"kW\"\ndnp3 = {{ point = \"analog_input\", index = 0 }}\n\n\
         [[tag]]\nname = \"OS.SP\"\ndevice = \"OS\"\nwritable = true\nwrite_role = \"operator\"\nmin = 0.0\nmax = 100.0\n\
         dnp3 = {{ point = \"analog_output\", index = 0, command = \"analog_output\" }}\n\n\
         [[tag]]\nname = \"OS.E\"\ndevice = \"OS\"\ndnp3 = {{ point = \"counter\", index = 0 }}\n"
    );
    assert_eq!(problems(MAIN, &tags), Vec::<String>::new());
}

#[test]
fn dnp3_points_are_checked_against_their_tag_and_device() {
    let tags = format!(
        "{OUTSTATION}\n[device.dnp3]\noutstation_address = 1\nresponse_timeout_ms = 10\ncommand_timeout_s = 0.5\n\n\
         [[tag]]\nname = \"OS.A\"\ndevice = \"OS\"\ntype = \"f32\"\ndnp3 = {{ point = \"binary_input\", index = 5 }}\n\n\
         [[tag]]\nname = \"OS.B\"\ndevice = \"OS\"\ndnp3 = {{ point = \"binary_input\", index = 5, command = \"crob\" }}\n\n\
         [[tag]]\nname = \"OS.C\"\ndevice = \"OS\"\nkind = \"coil\"\naddress = 3\n\n\
         [[tag]]\nname = \"OS.D\"\ndevice = \"OS\"\nwritable = true\nwrite_role = \"operator\"\n\
         dnp3 = {{ point = \"analog_output\", index = 1, command = \"analog_output\", op = \"pulse\" }}\n\n\
         [[tag]]\nname = \"OS.F\"\ndevice = \"OS\"\nwritable = true\nwrite_role = \"operator\"\n\
         dnp3 = {{ point = \"binary_output\", index = 2, command = \"crob\", on_ms = 100 }}\n\n\
         [[tag]]\nname = \"OS.G\"\ndevice = \"OS\"\ndnp3 = {{ point = \"counter\", index = 2, command_index = 4 }}\n\n\
         {DEVICE}\n[[tag]]\nname = \"D.X\"\ndevice = \"D1\"\nkind = \"coil\"\naddress = 0\ndnp3 = {{ point = \"binary_input\", index = 9 }}\n"
    );
    assert_problems(
        MAIN,
        &tags,
        &[
            "DIR/tags.toml:7:22: error: device 'OS': outstation_address 1 is the master_address too",
            "DIR/tags.toml:8:23: error: device 'OS': response_timeout_ms must be 100 to 600000",
            "DIR/tags.toml:9:21: error: device 'OS': command_timeout_s must be 1 to 600 seconds",
            "DIR/tags.toml:14:8: error: tag 'OS.A': a DNP3 binary_input point cannot carry a f32 value (use type = \"bool\")",
            "DIR/tags.toml:20:42: error: tag 'OS.B': point binary_input index 5 of device 'OS' is used by tag 'OS.A' too (at DIR/tags.toml:15:42)",
            "DIR/tags.toml:20:55: error: tag 'OS.B': command crob is set on a read-only tag (set writable = true and write_role)",
            "DIR/tags.toml:23:8: error: tag 'OS.C': a tag of DNP3 device 'OS' needs dnp3 = { point = \"binary_input\", index = … }",
            "DIR/tags.toml:25:8: error: tag 'OS.C': kind is a Modbus setting; device 'OS' speaks DNP3 (use dnp3 = { point = …, index = … })",
            "DIR/tags.toml:26:11: error: tag 'OS.C': address is a Modbus setting; device 'OS' speaks DNP3 (use dnp3 = { point = …, index = … })",
            "DIR/tags.toml:33:78: error: tag 'OS.D': op belongs to a CROB (command = \"crob\")",
            "DIR/tags.toml:40:72: error: tag 'OS.F': on_ms does not apply to op = \"latch\"",
            "DIR/tags.toml:45:56: error: tag 'OS.G': command_index is for a tag with a command",
            "DIR/tags.toml:57:18: error: tag 'D.X': dnp3 is for tags of protocol = \"dnp3\" devices, and device 'D1' is not one",
        ],
    );
}

#[test]
fn a_dnp3_key_that_does_not_belong_is_located() {
    let tags = format!(
        "{OUTSTATION}\n[[tag]]\nname = \"OS.E\"\ndevice = \"OS\"\ndnp3 = {{ point = \"counter\", index = 1, colour = \"red\" }}\n"
    );
    assert_problems(
        MAIN,
        &tags,
        &[
            "DIR/tags.toml:9:40: error: tag 'OS.E': unknown field `colour`, expected one of `point`, `index`, `command`, `command_index`, `select`, `op`, `on_ms`, `off_ms`",
        ],
    );
}

#[test]
fn a_dnp3_outstation_on_a_serial_line_loads_and_has_the_line_to_itself() {
    let serial = "[[device]]\nname = \"OS\"\nprotocol = \"dnp3\"\n\n[device.serial]\nport = \"/dev/ttyS1\"\nbaud = 19200\n\n\
                  [[tag]]\nname = \"OS.P\"\ndevice = \"OS\"\ndnp3 = { point = \"analog_input\", index = 0 }\n";
    assert_eq!(problems(MAIN, serial), Vec::<String>::new());

    let tags = "[[device]]\nname = \"OS\"\nprotocol = \"dnp3\"\naddress = \"127.0.0.1:20000\"\n\n[device.serial]\nport = \"/dev/ttyS1\"\n\n\
                [[device]]\nname = \"OS2\"\nprotocol = \"dnp3\"\n\n[device.serial]\nport = \"/dev/ttyS2\"\nstop_bits = 3\n\n\
                [[device]]\nname = \"M1\"\nprotocol = \"rtu\"\nunit_id = 2\n\n[device.serial]\nport = \"/dev/ttyS2\"\n\n\
                [[device]]\nname = \"OS3\"\nprotocol = \"dnp3\"\n\n\
                [[device]]\nname = \"T1\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:502\"\n\n[device.serial]\nport = \"/dev/ttyS3\"\n";
    assert_problems(
        MAIN,
        tags,
        &[
            "DIR/tags.toml:4:11: error: device 'OS': a dnp3 device has either address (TCP) or [device.serial], not both",
            "DIR/tags.toml:15:13: error: device 'OS2': stop_bits must be 1 or 2",
            "DIR/tags.toml:23:8: error: device 'M1': serial port /dev/ttyS2 is already used by device 'OS2' (at DIR/tags.toml:10:8); a DNP3 outstation needs a serial port of its own",
            "DIR/tags.toml:26:8: error: device 'OS3': a dnp3 device needs address = \"host:port\" or a [device.serial] table",
            "DIR/tags.toml:30:8: error: device 'T1': [device.serial] is only for protocol = \"rtu\" or \"dnp3\"",
        ],
    );
}
