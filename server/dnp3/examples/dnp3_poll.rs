//! A throwaway DNP3 master over a plain TCP socket, built on this crate's
//! codec and state machine, to try them against third-party outstations
//! (see PEERS.md). Not part of gridscada's runtime.
//!
//! cargo run -p gridscada-dnp3 --example dnp3_poll -- 127.0.0.1:20000 \
//!     [--master 1] [--outstation 1024] [--seconds 8] [--crob INDEX] [--sbo] \
//!     [--analog INDEX VALUE] [--event-period SECONDS]

use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use gridscada_dnp3::master::{Command, CommandMode};
use gridscada_dnp3::objects::{AnalogOutput, Crob};
use gridscada_dnp3::{Action, Clock, CommandObject, Master, MasterConfig};

fn clock() -> Clock {
    Clock {
        mono: Instant::now(),
        unix_ms: SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_millis() as u64)
            .unwrap_or(0),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let addr = args.first().cloned().unwrap_or("127.0.0.1:20000".into());
    let opt = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let num = |name: &str, default: u64| opt(name).map_or(default, |v| v.parse().unwrap());
    let cfg = MasterConfig {
        master_address: num("--master", 1) as u16,
        outstation_address: num("--outstation", 1024) as u16,
        // --event-period 0: no event polls (rely on unsolicited responses).
        event_period: Some(num("--event-period", 2))
            .filter(|&s| s > 0)
            .map(Duration::from_secs),
        ..MasterConfig::default()
    };
    let seconds = num("--seconds", 8);
    let mode = if args.iter().any(|a| a == "--sbo") {
        CommandMode::SelectBeforeOperate
    } else {
        CommandMode::DirectOperate
    };
    let mut commands = Vec::new();
    if let Some(i) = opt("--crob") {
        commands.push(Command {
            id: 1,
            index: i.parse().unwrap(),
            object: CommandObject::Crob(Crob::latch(true)),
            mode,
        });
    }
    if let Some(i) = args.iter().position(|a| a == "--analog") {
        commands.push(Command {
            id: 2,
            index: args[i + 1].parse().unwrap(),
            object: CommandObject::Analog(AnalogOutput::F64(args[i + 2].parse().unwrap())),
            mode,
        });
    }

    let mut s = TcpStream::connect(&addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
    let mut m = Master::new(cfg);
    let start = Instant::now();
    let mut actions = m.connected(clock());
    let mut buf = [0u8; 4096];
    let (mut values, mut timeouts, mut malformed, mut sent) = (0, 0, 0, 0);
    while start.elapsed() < Duration::from_secs(seconds) {
        for a in actions.drain(..) {
            match a {
                Action::Send(b) => {
                    sent += 1;
                    println!("-> {}", hex(&b));
                    s.write_all(&b).expect("write");
                }
                Action::Measurements(ms) => {
                    for x in ms {
                        values += 1;
                        println!(
                            "   {:?} {} = {:?} [{}] time {:?}{}",
                            x.kind,
                            x.index,
                            x.value,
                            x.flags.quality().1,
                            x.time,
                            if x.is_event { " (event)" } else { "" }
                        );
                    }
                }
                Action::CommandOutcome { id, result } => {
                    println!("   command {id}: {:?}", result.map_err(|e| e.to_string()))
                }
                Action::IinChanged { before, now } => println!("   IIN {before} -> {now}"),
                Action::Report(r) => {
                    let t = r.to_string();
                    timeouts += usize::from(t.starts_with("no response"));
                    malformed += usize::from(t.starts_with("malformed"));
                    println!("   report: {t}");
                }
                Action::Timer(_) => {}
                Action::Disconnect(reason) => {
                    println!("   disconnect: {reason}");
                    return;
                }
            }
        }
        if start.elapsed() > Duration::from_secs(2) && !m.is_busy() {
            for c in commands.drain(..) {
                actions.extend(m.command(c, clock()));
            }
        }
        match s.read(&mut buf) {
            Ok(0) => {
                println!("   connection closed by the outstation");
                break;
            }
            Ok(n) => {
                println!("<- {}", hex(&buf[..n]));
                actions.extend(m.received(&buf[..n], clock()));
            }
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(e) => panic!("read: {e}"),
        }
        actions.extend(m.tick(clock()));
    }
    println!(
        "summary: {sent} sends, {values} values, {timeouts} timeouts, {malformed} malformed, IIN {}",
        m.iin()
    );
}

fn hex(b: &[u8]) -> String {
    b.iter()
        .map(|x| format!("{x:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}
