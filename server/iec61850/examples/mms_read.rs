//! Associates with an IED and reads the given references:
//! `cargo run -p gridscada-iec61850 --example mms_read -- 127.0.0.1:102 TESTLD0/GGIO1$MX$AnIn1$mag$f`.
use std::time::Duration;

use gridscada_iec61850::client::Connection;
use gridscada_iec61850::{ObjectName, Request};

#[tokio::main(flavor = "current_thread")]
async fn main() {
    let mut args = std::env::args().skip(1);
    let address = args.next().expect("address");
    let t = Duration::from_secs(5);
    let (c, _reports) = Connection::open(&address, Default::default(), t)
        .await
        .expect("associate");
    println!("negotiated {:?}", c.negotiated);
    for r in args {
        // `LD/item=b:1` writes a boolean, `=i:N` an integer, `=u:N` unsigned.
        if let Some((r, v)) = r.split_once('=') {
            let (d, i) = r.split_once('/').expect("LD/item");
            let data = match v.split_once(':') {
                Some(("b", x)) => gridscada_iec61850::Data::Boolean(x == "1"),
                Some(("i", x)) => gridscada_iec61850::Data::Integer(x.parse().expect("int")),
                Some(("u", x)) => gridscada_iec61850::Data::Unsigned(x.parse().expect("uint")),
                _ => panic!("value b:0|1, i:N or u:N"),
            };
            let name = ObjectName::Domain(d.into(), i.into());
            println!(
                "write {r}: {:?}",
                c.request(&Request::Write(name, data), t).await
            );
            continue;
        }
        let (d, i) = r.split_once('/').expect("LD/item");
        let name = ObjectName::Domain(d.into(), i.into());
        println!(
            "{r}: {:?}",
            c.request(&Request::Read(vec![name.clone()]), t).await
        );
        println!(
            "  type: {:?}",
            c.request(&Request::GetVariableAccessAttributes(name), t)
                .await
        );
    }
    println!(
        "domains: {:?}",
        c.request(
            &Request::GetNameList {
                class: 9,
                domain: None,
                continue_after: None
            },
            t
        )
        .await
    );
    c.conclude(t).await;
}
