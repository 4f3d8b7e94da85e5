//! The poller against in-process tokio-modbus TCP servers.

use crate::common;

use std::sync::Arc;
use std::time::Duration;

use common::*;
use gridscada_modbus::FieldIo;
use gridscada_tagdb::{QualityCode, SystemClock, TagDb, Value, WriteError};

const SECOND: Duration = Duration::from_secs(1);

fn value(db: &TagDb, name: &str) -> Option<Value> {
    db.get_by_name(name)
        .filter(|s| s.quality.is_good())
        .map(|s| s.value)
}

fn bad_reason(db: &TagDb, name: &str) -> Option<String> {
    db.get_by_name(name)
        .filter(|s| s.quality.code == QualityCode::Bad)
        .map(|s| s.quality.reason.as_deref().unwrap_or("").to_string())
}

fn start(plant: &gridscada_config::Plant) -> (Arc<TagDb>, FieldIo) {
    let db = tagdb(plant);
    let io = FieldIo::start(plant, Arc::clone(&db), Arc::new(SystemClock)).expect("start");
    (db, io)
}

fn words_be(bytes: &[u8]) -> Vec<u16> {
    bytes
        .chunks(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect()
}

fn typed_tags() -> String {
    let w = "writable = true\nwrite_role = \"operator\"\n";
    let t = |name: &str, kind: &str, addr: u32, extra: &str| {
        format!("[[tag]]\nname = \"D.{name}\"\ndevice = \"D\"\nkind = \"{kind}\"\naddress = {addr}\n{extra}\n")
    };
    [
        t("Coil", "coil", 0, w),
        t("DI", "discrete_input", 0, ""),
        t(
            "I16",
            "holding_register",
            0,
            &format!("type = \"i16\"\n{w}"),
        ),
        t(
            "U16",
            "holding_register",
            1,
            &format!("type = \"u16\"\n{w}"),
        ),
        t(
            "I32",
            "holding_register",
            2,
            &format!("type = \"i32\"\nword_order = \"little\"\n{w}"),
        ),
        t(
            "U32",
            "holding_register",
            4,
            &format!("type = \"u32\"\nbyte_order = \"little\"\n{w}"),
        ),
        t(
            "I64",
            "holding_register",
            6,
            &format!("type = \"i64\"\n{w}"),
        ),
        t(
            "U64",
            "holding_register",
            10,
            &format!("type = \"u64\"\n{w}"),
        ),
        t(
            "F32",
            "holding_register",
            14,
            &format!("type = \"f32\"\n{w}"),
        ),
        t(
            "F64",
            "holding_register",
            16,
            &format!("type = \"f64\"\n{w}"),
        ),
        t(
            "Str",
            "holding_register",
            20,
            &format!("type = \"string\"\nlength = 4\n{w}"),
        ),
        t("Bit", "holding_register", 30, &format!("bit = 5\n{w}")),
        t(
            "Scaled",
            "input_register",
            0,
            "type = \"i16\"\nscale = 0.1\noffset = -40.0\n",
        ),
        t("Big", "input_register", 1, "type = \"u64\"\n"),
    ]
    .concat()
}

#[tokio::test]
async fn every_data_type_reads_and_writes_with_read_back() {
    let bank = Bank::with_units(&[1]);
    bank.unit(1, |u| {
        u.coils[0] = true;
        u.discrete[0] = true;
        u.holding[0] = (-1234i16) as u16;
        u.holding[1] = 54321;
        let i32w = words_be(&(-123_456_789i32).to_be_bytes());
        u.holding[2] = i32w[1]; // little word order: low word first
        u.holding[3] = i32w[0];
        u.holding[4] = 0xADDE; // 0xDEADBEEF with bytes swapped in each word
        u.holding[5] = 0xEFBE;
        u.holding[6..10].copy_from_slice(&words_be(&(-9_000_000_000_000i64).to_be_bytes()));
        u.holding[10..14].copy_from_slice(&words_be(&12_345_678_901_234u64.to_be_bytes()));
        u.holding[14..16].copy_from_slice(&words_be(&230.5f32.to_be_bytes()));
        u.holding[16..20].copy_from_slice(&words_be(&49.95f64.to_be_bytes()));
        u.holding[20..24].copy_from_slice(&words_be(b"ABCDEFG\0"));
        u.holding[30] = 1 << 5 | 1;
        u.input[0] = 655;
        u.input[1..5].copy_from_slice(&[0xFFFF, 0xFFFF, 0xFFFF, 0xFFFE]);
    });
    let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    let plant = plant(&format!(
        "{}{}",
        device("D", addr, 1, 50, 500),
        typed_tags()
    ));
    let (db, io) = start(&plant);

    eventually("all tags read", 5 * SECOND, || {
        plant
            .tags
            .iter()
            .all(|t| value(&db, t.name.get_ref()).is_some())
    })
    .await;
    assert_eq!(value(&db, "D.Coil"), Some(Value::Bool(true)));
    assert_eq!(value(&db, "D.DI"), Some(Value::Bool(true)));
    assert_eq!(value(&db, "D.I16"), Some(Value::Int(-1234)));
    assert_eq!(value(&db, "D.U16"), Some(Value::Int(54321)));
    assert_eq!(value(&db, "D.I32"), Some(Value::Int(-123_456_789)));
    assert_eq!(value(&db, "D.U32"), Some(Value::Int(0xDEAD_BEEF)));
    assert_eq!(value(&db, "D.I64"), Some(Value::Int(-9_000_000_000_000)));
    assert_eq!(value(&db, "D.U64"), Some(Value::Int(12_345_678_901_234)));
    assert_eq!(value(&db, "D.F32"), Some(Value::Float(230.5)));
    assert_eq!(value(&db, "D.F64"), Some(Value::Float(49.95)));
    assert_eq!(value(&db, "D.Str"), Some(Value::from("ABCDEFG")));
    assert_eq!(value(&db, "D.Bit"), Some(Value::Bool(true)));
    let Some(Value::Float(scaled)) = value(&db, "D.Scaled") else {
        panic!("scaled tag is not a float")
    };
    assert!((scaled - 25.5).abs() < 1e-9);
    // Exact above i64::MAX, never rounded through a float.
    assert_eq!(value(&db, "D.Big"), Some(Value::UInt(u64::MAX - 1)));

    // Writes: each is confirmed by read-back, and the wire image is right.
    let w = io.writer();
    let cases: Vec<(&str, Value)> = vec![
        ("D.Coil", Value::Bool(false)),
        ("D.I16", Value::Int(-2)),
        ("D.U16", Value::Int(7)),
        ("D.I32", Value::Int(-70_000)),
        ("D.U32", Value::Int(0x0102_0304)),
        ("D.I64", Value::Int(-5)),
        ("D.U64", Value::Int(1 << 40)),
        // Above 2^53 and above i64::MAX: the write and its read-back are exact.
        ("D.U64", Value::UInt(12_345_678_901_234_567_891)),
        ("D.F32", Value::Float(-1.25)),
        ("D.F64", Value::Float(1.0e-3)),
        ("D.Str", Value::from("xy")),
        ("D.Bit", Value::Bool(false)),
    ];
    for (tag, v) in &cases {
        let sample = w
            .write(tag, v.clone())
            .await
            .unwrap_or_else(|e| panic!("{tag}: {e}"));
        assert!(sample.quality.is_good());
        assert_eq!(&sample.value, v, "{tag}");
        assert_eq!(value(&db, tag).as_ref(), Some(v), "{tag} in the tag db");
    }
    bank.unit(1, |u| {
        assert!(!u.coils[0]);
        assert_eq!(u.holding[0], 0xFFFE);
        let i32w = words_be(&(-70_000i32).to_be_bytes());
        assert_eq!(&u.holding[2..4], &[i32w[1], i32w[0]]);
        assert_eq!(&u.holding[4..6], &[0x0201, 0x0403]);
        assert_eq!(&u.holding[6..10], &[0xFFFF, 0xFFFF, 0xFFFF, 0xFFFB]);
        assert_eq!(&u.holding[10..14], &[0xAB54, 0xA98C, 0xEB1F, 0x0AD3]);
        assert_eq!(
            &u.holding[14..16],
            words_be(&(-1.25f32).to_be_bytes()).as_slice()
        );
        assert_eq!(&u.holding[20..24], &[0x7879, 0, 0, 0]);
        // Only bit 5 cleared; bit 0 kept (read-modify-write).
        assert_eq!(u.holding[30], 1);
    });

    // Checks before the wire.
    assert!(matches!(
        w.write("D.U16", Value::Int(70_000)).await,
        Err(WriteError::BadValue { .. })
    ));
    assert!(matches!(
        w.write("D.Scaled", Value::Float(1.0)).await,
        Err(WriteError::ReadOnly(_))
    ));
    assert!(matches!(
        w.write("D.Nope", Value::Int(1)).await,
        Err(WriteError::UnknownTag(_))
    ));
    let stats = io.stats();
    assert!(stats.device("D").unwrap().requests > 0);
    io.shutdown().await;
}

#[tokio::test]
async fn exception_turns_tags_bad_with_the_exception_named() {
    let bank = Bank::with_units(&[1]);
    bank.unit(1, |u| {
        u.readable_below = 500;
        u.holding[0] = 42;
    });
    let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    let tags = "[[tag]]\nname = \"D.Ok\"\ndevice = \"D\"\nkind = \"holding_register\"\naddress = 0\n\n\
                [[tag]]\nname = \"D.Missing\"\ndevice = \"D\"\nkind = \"holding_register\"\naddress = 600\n";
    let plant = plant(&format!("{}{tags}", device("D", addr, 1, 50, 500)));
    let (db, io) = start(&plant);
    eventually("exception reported", 5 * SECOND, || {
        bad_reason(&db, "D.Missing").is_some_and(|r| r.contains("illegal data address"))
    })
    .await;
    eventually("the other block is good", 5 * SECOND, || {
        value(&db, "D.Ok") == Some(Value::Int(42))
    })
    .await;
    // An answering device is connected, whatever the exception.
    assert_eq!(value(&db, "D.Comm.Connected"), Some(Value::Bool(true)));
    assert!(io.stats().device("D").unwrap().exceptions > 0);
    io.shutdown().await;
}

#[tokio::test]
async fn silent_unit_goes_bad_while_its_neighbour_keeps_its_scan_rate() {
    let bank = Bank::with_units(&[1, 2]);
    bank.unit(1, |u| u.holding[0] = 11);
    bank.unit(2, |u| u.holding[0] = 22);
    let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    let period = Duration::from_millis(200);
    let tags = "[[tag]]\nname = \"A.V\"\ndevice = \"A\"\nkind = \"holding_register\"\naddress = 0\n\n\
                [[tag]]\nname = \"B.V\"\ndevice = \"B\"\nkind = \"holding_register\"\naddress = 0\n";
    let plant = plant(&format!(
        "{}{}{tags}",
        device("A", addr, 1, 200, 60),
        device("B", addr, 2, 200, 60)
    ));
    let (db, io) = start(&plant);
    eventually("both good", 5 * SECOND, || {
        value(&db, "A.V") == Some(Value::Int(11)) && value(&db, "B.V") == Some(Value::Int(22))
    })
    .await;

    bank.unit(2, |u| u.silent = true);
    let silenced = tokio::time::Instant::now();
    let scans_before = io.stats().device("A").unwrap().scans;
    // Bad within two scan periods (plus scheduling slack for a loaded machine).
    eventually("B bad", 2 * period + Duration::from_millis(150), || {
        bad_reason(&db, "B.V").is_some()
    })
    .await;
    let reason = bad_reason(&db, "B.V").unwrap();
    assert!(
        reason.contains("timeout") || reason.contains("no answer"),
        "{reason}"
    );
    assert_eq!(value(&db, "B.Comm.Connected"), Some(Value::Bool(false)));

    // Over the next two seconds A keeps (nearly) its 5 scans a second and
    // stays Good, while B is only probed now and then.
    tokio::time::sleep(2 * SECOND).await;
    let elapsed = silenced.elapsed().as_secs_f64();
    let a = io.stats().device("A").unwrap().clone();
    let b = io.stats().device("B").unwrap().clone();
    let a_scans = (a.scans - scans_before) as f64;
    assert!(
        a_scans >= 0.8 * elapsed / period.as_secs_f64(),
        "A scanned {a_scans} times in {elapsed:.2}s"
    );
    assert_eq!(value(&db, "A.V"), Some(Value::Int(11)));
    assert!(b.timeouts >= 2);
    assert!(
        b.timeouts < 8,
        "B is backed off, not polled at full rate: {} timeouts",
        b.timeouts
    );

    // B comes back: Good again via a probe.
    bank.unit(2, |u| u.silent = false);
    eventually("B good again", 20 * SECOND, || {
        value(&db, "B.V") == Some(Value::Int(22))
    })
    .await;
    io.shutdown().await;
}

#[tokio::test]
async fn server_killed_then_restarted_reconnects() {
    let bank = Bank::with_units(&[1]);
    bank.unit(1, |u| u.holding[0] = 5);
    let (addr, server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    let tags =
        "[[tag]]\nname = \"D.V\"\ndevice = \"D\"\nkind = \"holding_register\"\naddress = 0\n";
    let plant = plant(&format!("{}{tags}", device("D", addr, 1, 100, 200)));
    let (db, io) = start(&plant);
    eventually("good", 5 * SECOND, || {
        value(&db, "D.V") == Some(Value::Int(5))
    })
    .await;

    server.abort();
    let _ = server.await;
    eventually("bad after the server died", 5 * SECOND, || {
        bad_reason(&db, "D.V").is_some()
    })
    .await;
    tokio::time::sleep(Duration::from_millis(700)).await;
    assert!(bad_reason(&db, "D.V").is_some());

    bank.unit(1, |u| u.holding[0] = 6);
    let (_addr, _server) = serve(Arc::clone(&bank), &addr.to_string()).await;
    eventually("good again", 15 * SECOND, || {
        value(&db, "D.V") == Some(Value::Int(6))
    })
    .await;
    let link = io.stats().links[0].clone();
    assert!(link.connects >= 2, "{link:?}");
    io.shutdown().await;
}

#[tokio::test]
async fn late_reply_is_never_taken_for_the_next_answer() {
    let bank = Bank::with_units(&[1]);
    bank.unit(1, |u| {
        u.holding[0] = 1000; // block one
        u.holding[100] = 2000; // block two: a late block-one reply would look like this
    });
    let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    let tags = "[[tag]]\nname = \"D.A\"\ndevice = \"D\"\nkind = \"holding_register\"\naddress = 0\n\n\
                [[tag]]\nname = \"D.B\"\ndevice = \"D\"\nkind = \"holding_register\"\naddress = 100\n";
    let mut text = format!("{}{tags}", device("D", addr, 1, 100, 80));
    text = text.replace("retries = 1", "retries = 3");
    let plant = plant(&text);
    let (db, io) = start(&plant);
    let ids = [db.id("D.A").unwrap(), db.id("D.B").unwrap()];
    let mut sub = db.subscribe(&ids);
    eventually("good", 5 * SECOND, || {
        value(&db, "D.B") == Some(Value::Int(2000))
    })
    .await;

    // Three times: the reply to block two comes after its timeout, while the
    // poller is already waiting for block one of the next scan (same unit,
    // same function, same length: only the transaction id tells them apart).
    for _ in 0..3 {
        bank.unit(1, |u| {
            u.delay = Duration::from_millis(150);
            u.delay_once_at = Some(100);
        });
        eventually("delay used", 5 * SECOND, || {
            bank.unit(1, |u| u.delay_once_at.is_none())
        })
        .await;
        tokio::time::sleep(Duration::from_millis(400)).await;
    }
    eventually("late replies seen", 5 * SECOND, || {
        io.stats().links[0].late_replies >= 1
    })
    .await;
    // Every Good sample ever published carried the right value.
    while let Some(update) = sub.try_recv() {
        for (id, s) in &update.batch().changes {
            if s.quality.is_good() {
                let want = if *id == ids[0] { 1000 } else { 2000 };
                assert_eq!(
                    s.value,
                    Value::Int(want),
                    "tag {id:?} got a mis-assigned reply"
                );
            }
        }
    }
    assert_eq!(value(&db, "D.A"), Some(Value::Int(1000)));
    assert_eq!(value(&db, "D.B"), Some(Value::Int(2000)));
    io.shutdown().await;
}

#[tokio::test]
async fn write_whose_read_back_differs_is_a_mismatch_and_never_good() {
    let bank = Bank::with_units(&[1]);
    bank.unit(1, |u| {
        u.holding[0] = 100;
        u.ignore_writes = true;
    });
    let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    let tags = "[[tag]]\nname = \"D.Setpoint_kW\"\ndevice = \"D\"\nkind = \"holding_register\"\naddress = 0\n\
                type = \"i16\"\nscale = 0.5\nwritable = true\nwrite_role = \"operator\"\n";
    let plant = plant(&format!("{}{tags}", device("D", addr, 1, 50, 300)));
    let (db, io) = start(&plant);
    let id = db.id("D.Setpoint_kW").unwrap();
    eventually("good", 5 * SECOND, || {
        value(&db, "D.Setpoint_kW") == Some(Value::Float(50.0))
    })
    .await;
    let mut sub = db.subscribe(&[id]);
    let err = io
        .writer()
        .write("D.Setpoint_kW", Value::Float(60.0))
        .await
        .unwrap_err();
    match &err {
        WriteError::Mismatch {
            written, read_back, ..
        } => {
            assert_eq!(written, "60");
            assert_eq!(read_back, "50");
        }
        other => panic!("expected a mismatch, got {other}"),
    }
    tokio::time::sleep(Duration::from_millis(200)).await;
    while let Some(update) = sub.try_recv() {
        for (_, s) in &update.batch().changes {
            assert_ne!(s.value, Value::Float(60.0), "unconfirmed value shown");
        }
    }
    // The device takes writes again: confirmed.
    bank.unit(1, |u| u.ignore_writes = false);
    let s = io
        .writer()
        .write("D.Setpoint_kW", Value::Float(60.0))
        .await
        .unwrap();
    assert_eq!(s.value, Value::Float(60.0));
    assert_eq!(bank.unit(1, |u| u.holding[0]), 120);
    io.shutdown().await;
}

#[tokio::test]
async fn writes_jump_ahead_of_queued_reads() {
    let bank = Bank::with_units(&[1]);
    bank.unit(1, |u| u.delay = Duration::from_millis(15));
    let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    // Twenty blocks (gaps beyond max_gap): one scan is twenty requests.
    let mut tags = String::new();
    for i in 0..20 {
        tags += &format!(
            "[[tag]]\nname = \"D.R{i}\"\ndevice = \"D\"\nkind = \"holding_register\"\naddress = {}\n\n",
            i * 100
        );
    }
    tags += "[[tag]]\nname = \"D.Cmd\"\ndevice = \"D\"\nkind = \"coil\"\naddress = 0\nwritable = true\nwrite_role = \"operator\"\n";
    let text = format!("{}{tags}", device("D", addr, 1, 2000, 500))
        .replace("retries = 1", "retries = 1\nmax_gap = 4");
    let plant = plant(&text);
    let (_db, io) = start(&plant);
    // Wait for the second scan to begin: its first block read.
    eventually("a scan under way", 10 * SECOND, || {
        bank.log
            .lock()
            .iter()
            .filter(|(_, fc, a)| *fc == 3 && *a == 0)
            .count()
            >= 2
    })
    .await;
    let at_call = bank.log.lock().len();
    io.writer().write("D.Cmd", Value::Bool(true)).await.unwrap();
    let log = bank.log.lock().clone();
    let write_at = log
        .iter()
        .position(|(_, fc, _)| *fc == 5)
        .expect("write sent");
    let reads_between = log[at_call..write_at]
        .iter()
        .filter(|(_, fc, _)| *fc == 3)
        .count();
    assert!(
        reads_between <= 1,
        "{reads_between} queued reads went before the write"
    );
    // The scan went on after the write.
    let reads_after = log[write_at..].iter().filter(|(_, fc, _)| *fc == 3).count();
    assert!(reads_after >= 1 || log.len() == write_at + 2);
    io.shutdown().await;
}

#[tokio::test]
async fn status_tags_are_registered_and_kept() {
    let bank = Bank::with_units(&[1]);
    let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    let tags = "[[tag]]\nname = \"D.V\"\ndevice = \"D\"\nkind = \"input_register\"\naddress = 3\n";
    let plant = plant(&format!("{}{tags}", device("D", addr, 1, 50, 300)));
    let names: Vec<String> = gridscada_field::device_status_tags(&plant)
        .iter()
        .map(|m| m.name.to_string())
        .collect();
    assert_eq!(
        names,
        [
            "D.Comm.Connected",
            "D.Comm.LastError",
            "D.Comm.ResponseMs",
            "D.Comm.Requests",
            "D.Comm.Errors",
            "D.Comm.Timeouts",
            "D.Comm.Overruns",
            "D.Comm.Retries"
        ]
    );
    let (db, io) = start(&plant);
    eventually(
        "requests counted",
        5 * SECOND,
        || matches!(value(&db, "D.Comm.Requests"), Some(Value::Int(n)) if n >= 3),
    )
    .await;
    assert_eq!(value(&db, "D.Comm.Connected"), Some(Value::Bool(true)));
    assert_eq!(value(&db, "D.Comm.Errors"), Some(Value::Int(0)));
    assert!(matches!(value(&db, "D.Comm.ResponseMs"), Some(Value::Float(ms)) if ms >= 0.0));
    // A tag database without the status tags is refused with a clear error.
    let bare = Arc::new(
        TagDb::new(
            plant
                .tags
                .iter()
                .map(|t| gridscada_tagdb::TagMeta::new(t.name.get_ref().as_str(), t.value_kind())),
        )
        .unwrap(),
    );
    let err = FieldIo::start(&plant, bare, Arc::new(SystemClock))
        .err()
        .unwrap();
    assert!(err.to_string().contains("D.Comm.Connected"), "{err}");
    io.shutdown().await;
}

/// A write confirmed in the middle of a slow scan, after the scan read the
/// written register's block, must not be rolled back when the scan applies
/// its (older) batch: the tag never shows the old value again, and its
/// timestamps never go backwards. Deterministic: writes are served between
/// two blocks of a scan, and each request takes 60 ms.
#[tokio::test]
async fn a_write_interleaved_with_a_slow_scan_is_never_rolled_back() {
    let bank = Bank::with_units(&[1]);
    bank.unit(1, |u| {
        u.delay = Duration::from_millis(60);
        u.holding[0] = 333;
    });
    let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    // Block 0 holds the setpoint; eight more blocks make a scan of ~0.5 s.
    let mut tags = String::from(
        "[[tag]]\nname = \"D.Set\"\ndevice = \"D\"\nkind = \"holding_register\"\naddress = 0\nwritable = true\nwrite_role = \"operator\"\n\n",
    );
    for i in 1..9 {
        tags += &format!(
            "[[tag]]\nname = \"D.R{i}\"\ndevice = \"D\"\nkind = \"holding_register\"\naddress = {}\n\n",
            i * 100
        );
    }
    let text = format!("{}{tags}", device("D", addr, 1, 3000, 500))
        .replace("retries = 1", "retries = 1\nmax_gap = 4");
    let plant = plant(&text);
    let (db, io) = start(&plant);
    eventually("the first reading", 10 * SECOND, || {
        value(&db, "D.Set") == Some(Value::Int(333))
    })
    .await;
    // The second scan has read block 0 (the setpoint) and goes on with the others.
    eventually("a scan past its first block", 10 * SECOND, || {
        bank.log
            .lock()
            .iter()
            .filter(|(_, fc, a)| *fc == 3 && *a == 0)
            .count()
            >= 2
    })
    .await;
    let confirmed = io.writer().write("D.Set", Value::Int(411)).await.unwrap();
    assert_eq!(confirmed.value, Value::Int(411));
    // Watch through the end of that scan and into the next.
    let mut last_ts = confirmed.timestamp;
    let until = std::time::Instant::now() + Duration::from_millis(1500);
    while std::time::Instant::now() < until {
        let s = db.get_by_name("D.Set").unwrap();
        assert_eq!(
            s.value,
            Value::Int(411),
            "the written value was rolled back"
        );
        assert!(s.timestamp >= last_ts, "the tag's time went backwards");
        last_ts = s.timestamp;
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    io.shutdown().await;
}

/// `retries` repeats a read without an answer at once, before the device
/// counts as failing: the device receives exactly 1 + retries reads, the
/// repeats are counted in `Comm.Retries`, and only then do its tags go Bad.
#[tokio::test]
async fn retries_repeat_a_read_at_once_before_the_device_fails() {
    for retries in [0u32, 1, 3] {
        let bank = Bank::with_units(&[1]);
        bank.unit(1, |u| u.holding[0] = 7);
        let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
        let tags =
            "[[tag]]\nname = \"A.V\"\ndevice = \"A\"\nkind = \"holding_register\"\naddress = 0\n";
        let text = format!("{}{tags}", device("A", addr, 1, 1000, 80))
            .replace("retries = 1", &format!("retries = {retries}"));
        let (db, io) = start(&plant(&text));
        eventually("a first reading", 5 * SECOND, || {
            value(&db, "A.V") == Some(Value::Int(7))
        })
        .await;
        bank.unit(1, |u| u.silent = true);
        let from = bank.log.lock().len();
        eventually("A bad", 5 * SECOND, || bad_reason(&db, "A.V").is_some()).await;
        // Before the first probe (at least 500 ms after failing).
        let reads = bank.log.lock()[from..]
            .iter()
            .filter(|(_, fc, _)| *fc == 3)
            .count();
        assert_eq!(reads as u32, 1 + retries, "retries = {retries}");
        assert_eq!(
            db.get_by_name("A.Comm.Retries").map(|s| s.value),
            Some(Value::Int(i64::from(retries))),
            "retries = {retries}"
        );
        io.shutdown().await;
    }
}

/// A device that answers again after a long silence shows Good within two
/// scans and one probe interval: probes back off only up to the device's
/// `backoff_max_ms` (default twice its fastest scan, at least 2 s).
#[tokio::test]
async fn a_recovered_device_is_back_within_two_scans_and_one_probe_interval() {
    for (extra, cap) in [
        ("", Duration::from_secs(2)),
        ("backoff_max_ms = 500\n", Duration::from_millis(500)),
    ] {
        let bank = Bank::with_units(&[1]);
        bank.unit(1, |u| u.holding[0] = 5);
        let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
        let tags =
            "[[tag]]\nname = \"A.V\"\ndevice = \"A\"\nkind = \"holding_register\"\naddress = 0\n";
        let text = format!("{}{extra}{tags}", device("A", addr, 1, 200, 60));
        let (db, io) = start(&plant(&text));
        eventually("a first reading", 5 * SECOND, || {
            value(&db, "A.V") == Some(Value::Int(5))
        })
        .await;
        bank.unit(1, |u| u.silent = true);
        eventually("A bad", 5 * SECOND, || bad_reason(&db, "A.V").is_some()).await;
        // Long enough for an uncapped back-off to wait over 8 s.
        tokio::time::sleep(10 * SECOND).await;
        bank.unit(1, |u| u.silent = false);
        let back = tokio::time::Instant::now();
        let bound = 2 * Duration::from_millis(200) + cap + Duration::from_millis(600);
        eventually("A good again", bound, || {
            value(&db, "A.V") == Some(Value::Int(5))
        })
        .await;
        assert!(
            back.elapsed() <= bound,
            "back after {:?} (cap {cap:?})",
            back.elapsed()
        );
        io.shutdown().await;
    }
}

/// Tags stamped by a device clock carry the time the device read, from a
/// datetime clock and from a Unix-seconds clock; a tag set to `receive`, and
/// every tag once the clock reads nonsense, keep the receive time (and say
/// so with Uncertain quality).
#[tokio::test]
async fn device_clocks_stamp_the_tags_read_with_them() {
    let bank = Bank::with_units(&[1, 2]);
    bank.unit(1, |u| {
        u.holding[0..6].copy_from_slice(&[2024, 2, 29, 12, 0, 30]);
        u.holding[10] = 42;
        u.holding[11] = 43;
    });
    bank.unit(2, |u| {
        u.input[0..2].copy_from_slice(&words_be(&1_700_000_000u32.to_be_bytes()));
        u.input[5] = 7;
    });
    let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    let tags = |dev: &str, name: &str, kind: &str, address: u32, extra: &str| {
        format!("[[tag]]\nname = \"{dev}.{name}\"\ndevice = \"{dev}\"\nkind = \"{kind}\"\naddress = {address}\n{extra}\n")
    };
    let text = [
        device("M", addr, 1, 100, 500)
            .replace("[[device]]\n", "[[device]]\ntime_tag = \"M.Clock\"\n"),
        device("R", addr, 2, 100, 500),
        tags("M", "Clock", "holding_register", 0, "type = \"datetime\""),
        tags("M", "Energy", "holding_register", 10, ""),
        tags(
            "M",
            "Local",
            "holding_register",
            11,
            "time_tag = \"receive\"",
        ),
        tags("R", "Clock", "input_register", 0, "type = \"u32\""),
        tags("R", "Level", "input_register", 5, "time_tag = \"R.Clock\""),
    ]
    .concat();
    let plant = plant(&text);
    let (db, io) = start(&plant);
    eventually("all tags read", 5 * SECOND, || {
        ["M.Energy", "M.Local", "R.Level"]
            .iter()
            .all(|t| value(&db, t).is_some())
    })
    .await;
    let ts = |n: &str| db.get_by_name(n).unwrap().timestamp.as_millis();
    let leap_noon = gridscada_tagdb::Timestamp::parse_utc_text("2024-02-29T12:00:30Z").unwrap();
    assert_eq!(
        value(&db, "M.Clock"),
        Some(Value::from("2024-02-29T12:00:30Z"))
    );
    assert_eq!(ts("M.Energy"), leap_noon.as_millis());
    assert_eq!(ts("R.Level"), 1_700_000_000_000);
    // The clock itself and the opted-out tag keep the receive time (now).
    let now = gridscada_tagdb::Timestamp::now_utc().as_millis();
    assert!((now - ts("M.Local")).abs() < 5_000, "receive time");
    assert!(
        (now - ts("M.Clock")).abs() < 5_000,
        "the clock's own receive time"
    );
    // A clock that reads no date: its tags keep the receive time, flagged.
    bank.unit(1, |u| u.holding[1] = 13);
    eventually("the energy tag stamped on receipt", 5 * SECOND, || {
        db.get_by_name("M.Energy").is_some_and(|s| {
            s.quality.code == QualityCode::Uncertain
                && s.quality
                    .reason
                    .as_deref()
                    .unwrap_or("")
                    .contains("device clock M.Clock not read")
                && (now - s.timestamp.as_millis()).abs() < 5_000
        })
    })
    .await;
    assert!(bad_reason(&db, "M.Clock").unwrap().contains("not a date"));
    io.shutdown().await;
}

/// A dead device behind a gateway holds the shared connection for its
/// timeouts; its fast-scanned neighbour is late, but never shown as lost
/// (the comm alarm of a healthy device must not chatter).
#[tokio::test]
async fn a_dead_neighbour_behind_the_gateway_never_makes_a_healthy_device_look_lost() {
    let bank = Bank::with_units(&[1, 2]);
    bank.unit(1, |u| u.holding[0] = 1);
    bank.unit(2, |u| u.silent = true);
    let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    let tag = |dev: &str| {
        format!("[[tag]]\nname = \"{dev}.V\"\ndevice = \"{dev}\"\nkind = \"holding_register\"\naddress = 0\n")
    };
    let text = [
        device("IO", addr, 1, 100, 300),
        device("PA", addr, 2, 1000, 300),
        tag("IO"),
        tag("PA"),
    ]
    .concat();
    let (db, io) = start(&plant(&text));
    eventually("IO read", 5 * SECOND, || value(&db, "IO.V").is_some()).await;
    let connected = |n: &str| db.get_by_name(n).map(|s| s.value);
    // Every change, as the alarm engine sees them (a flicker may last
    // microseconds).
    let watched = [db.id("IO.Comm.Connected").unwrap(), db.id("IO.V").unwrap()];
    let mut changes = db.subscribe(&watched);
    let mut lost = 0;
    let started = tokio::time::Instant::now();
    // Long enough for several timeouts and probes of the dead neighbour.
    while started.elapsed() < 4 * SECOND {
        let Ok(Some(update)) = tokio::time::timeout(SECOND, changes.recv()).await else {
            continue;
        };
        let batch = match update {
            gridscada_tagdb::Update::Changes(b) | gridscada_tagdb::Update::Snapshot(b) => b,
        };
        lost += batch
            .changes
            .iter()
            .filter(|(_, s)| !s.quality.is_good() || s.value == Value::Bool(false))
            .count();
    }
    assert_eq!(connected("PA.Comm.Connected"), Some(Value::Bool(false)));
    assert!(bad_reason(&db, "PA.V").is_some());
    assert_eq!(lost, 0, "the healthy device looked lost {lost} times");
    io.shutdown().await;
}
