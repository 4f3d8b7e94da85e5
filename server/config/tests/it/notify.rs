//! `[[notify]]`: a full route loads with its defaults, and every mistake is
//! reported at its line with the route's name.

use std::fs;
use std::path::{Path, PathBuf};

use gridscada_config::{load_path, NotifyChannel, SmtpSecurity};

const TAGS: &str = r#"[[device]]
name = "D1"
protocol = "tcp"
address = "127.0.0.1:1502"

[[tag]]
name = "A.Volts"
device = "D1"
kind = "input_register"
address = 0
type = "f32"
"#;

fn plant_in(dir: &Path, extra: &str) -> PathBuf {
    fs::write(
        dir.join("gridscada.toml"),
        format!("tag_files = [\"tags.toml\"]\n{extra}"),
    )
    .unwrap();
    fs::write(dir.join("tags.toml"), TAGS).unwrap();
    dir.to_path_buf()
}

fn errors(extra: &str) -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    match load_path(&plant_in(dir.path(), extra)) {
        Ok(_) => vec![],
        Err(d) => d.iter().map(|d| d.to_string()).collect(),
    }
}

const EMAIL: &str = r#"
[[notify]]
name = "on-call"
channel = "email"
min_priority = 700
selections = ["SS1*"]
escalate_after_min = 10
hmi_url = "https://scada.example.com/scada"
utc_offset = "+01:00"
[notify.smtp]
host = "mail.example.com"
security = "starttls"
from = "SCADA <scada@example.com>"
username = "scada"
password_env = "GRIDSCADA_SMTP_PASSWORD"
[[notify.contact]]
name = "Day engineer"
address = "day@example.com"
on_call = ["mon-fri 07:00-19:00"]
[[notify.contact]]
name = "Night engineer"
address = "night@example.com"
"#;

#[test]
fn a_route_loads_with_its_defaults() {
    let dir = tempfile::tempdir().unwrap();
    let p = load_path(&plant_in(dir.path(), EMAIL)).unwrap();
    let n = &p.notify[0];
    assert_eq!(*n.channel.get_ref(), NotifyChannel::Email);
    let smtp = n.smtp.as_ref().unwrap();
    assert_eq!(*smtp.security.get_ref(), SmtpSecurity::Starttls);
    assert_eq!(smtp.port(), 587);
    assert_eq!(*n.flood_limit.get_ref(), 5);
    assert_eq!(*n.flood_window_s.get_ref(), 60);
    assert_eq!(*n.give_up_after_min.get_ref(), 1440);
    assert_eq!(n.contacts.len(), 2);
}

#[test]
fn mistakes_are_located() {
    let cases: &[(&str, &str, &str)] = &[
        (
            "channel = \"email\"",
            "channel = \"sms\"",
            "unknown variant `sms`",
        ),
        (
            "min_priority = 700",
            "min_priority = 2000",
            ":6:16: error: notify 'on-call': min_priority must be 0 to 1000",
        ),
        (
            "escalate_after_min = 10",
            "escalate_after_min = -1",
            ":8:22: error: notify 'on-call': escalate_after_min",
        ),
        (
            "utc_offset = \"+01:00\"",
            "utc_offset = \"CET\"",
            ":10:14: error: notify 'on-call': utc_offset: 'CET'",
        ),
        (
            "from = \"SCADA <scada@example.com>\"",
            "from = \"scada\"",
            ":14:8: error: notify 'on-call': smtp from 'scada'",
        ),
        (
            "password_env = \"GRIDSCADA_SMTP_PASSWORD\"",
            "password_env = \"my password\"",
            "password_env 'my password' is not an environment variable name",
        ),
        (
            "address = \"day@example.com\"",
            "address = \"day\"",
            ":19:11: error: notify 'on-call': contact 'Day engineer': 'day' is not an address",
        ),
        (
            "on_call = [\"mon-fri 07:00-19:00\"]",
            "on_call = [\"mon-fry\"]",
            ":20:12: error: notify 'on-call': contact 'Day engineer': on_call 'fry' is not a day",
        ),
        (
            "security = \"starttls\"",
            "security = \"none\"",
            "a password is never sent unencrypted",
        ),
        (
            "[notify.smtp]",
            "[notify.webhook]\nurl = \"ftp://x\"\nsecret_env = \"S\"\n[notify.smtp]",
            "[notify.webhook] is for channel \"webhook\"",
        ),
        (
            "hmi_url = \"https://scada.example.com/scada\"\n",
            "",
            "messages must link into the HMI: set hmi_url here or [server] public_origin",
        ),
        (
            "[[notify.contact]]\nname = \"Night engineer\"\naddress = \"night@example.com\"\n",
            "",
            "escalation needs a second [[notify.contact]]",
        ),
    ];
    for (from, to, want) in cases {
        assert!(EMAIL.contains(from), "{from}");
        let errs = errors(&EMAIL.replace(from, to));
        assert!(
            errs.iter().any(|e| e.contains(want)),
            "replacing {from:?} by {to:?}: want {want:?}, got {errs:#?}"
        );
        assert!(
            errs.iter().all(|e| e.contains("gridscada.toml:")),
            "{errs:#?}"
        );
    }
    // A second route of the same name; a webhook without its table.
    let errs = errors(&format!(
        "{EMAIL}\n[[notify]]\nname = \"on-call\"\nchannel = \"webhook\"\nhmi_url = \"http://h\"\n[[notify.contact]]\nname = \"x\"\naddress = \"x\"\n"
    ));
    assert!(
        errs.iter()
            .any(|e| e.contains("duplicate notify name 'on-call' (first defined at")),
        "{errs:#?}"
    );
    assert!(
        errs.iter()
            .any(|e| e.contains("channel \"webhook\" needs a [notify.webhook] table")),
        "{errs:#?}"
    );
    // public_origin stands in for hmi_url.
    let errs = errors(&format!(
        "[server]\npublic_origin = \"https://scada.example.com\"\n{}",
        EMAIL.replace("hmi_url = \"https://scada.example.com/scada\"\n", "")
    ));
    assert!(errs.is_empty(), "{errs:#?}");
}

const MQTT: &str = r#"
[mqtt]
broker = "mqtt://127.0.0.1:1883"
group = "G"

[[notify]]
name = "desk"
channel = "mqtt"
hmi_url = "https://scada.example.com"
[notify.mqtt]
topic = "site1/alarms"
[[notify.contact]]
name = "Desk"
address = "desk-1"
"#;

#[test]
fn an_mqtt_route_loads_and_its_mistakes_are_located() {
    let dir = tempfile::tempdir().unwrap();
    let p = load_path(&plant_in(dir.path(), MQTT)).unwrap();
    assert_eq!(*p.notify[0].channel.get_ref(), NotifyChannel::Mqtt);
    assert_eq!(
        p.notify[0].mqtt.as_ref().unwrap().topic.get_ref(),
        "site1/alarms"
    );
    let cases: &[(&str, &str, &str)] = &[
        (
            "topic = \"site1/alarms\"",
            "topic = \"site1/#\"",
            ":12:9: error: notify 'desk': mqtt topic 'site1/#' must not hold the wildcards + or #",
        ),
        (
            "topic = \"site1/alarms\"",
            "topic = \"spBv1.0/G\"",
            "the Sparkplug B namespace",
        ),
        (
            "[notify.mqtt]\ntopic = \"site1/alarms\"\n",
            "",
            ":9:11: error: notify 'desk': channel \"mqtt\" needs a [notify.mqtt] table",
        ),
        (
            "[mqtt]\nbroker = \"mqtt://127.0.0.1:1883\"\ngroup = \"G\"\n",
            "",
            "publishes on the broker of [mqtt], which is not configured",
        ),
        (
            "channel = \"mqtt\"",
            "channel = \"email\"",
            "[notify.mqtt] is for channel \"mqtt\"",
        ),
    ];
    for (from, to, want) in cases {
        let broken = MQTT.replacen(from, to, 1);
        assert_ne!(broken, MQTT, "case {from} did not apply");
        let errs = errors(&broken);
        assert!(
            errs.iter().any(|e| e.contains(want)),
            "{from} -> {to}: want '{want}', got {errs:#?}"
        );
    }
}
