//! Stand-in for `gridscada dispatch solve FILE` until the CLI is wired:
//! `dispatch_solve [dispatch solve] FILE|-`. Same solve as the CLI and the
//! live loop ([`gridscada_control::dispatch::solve_text`]).

use std::io::Read;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let path = match args.as_slice() {
        ["dispatch", "solve", p] | [p] => *p,
        _ => {
            eprintln!("usage: dispatch_solve [dispatch solve] FILE|-");
            std::process::exit(1);
        }
    };
    let text = if path == "-" {
        let mut s = String::new();
        if let Err(e) = std::io::stdin().read_to_string(&mut s) {
            eprintln!("error: cannot read stdin: {e}");
            std::process::exit(1);
        }
        s
    } else {
        match std::fs::read_to_string(path) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("error: cannot read {path}: {e}");
                std::process::exit(1);
            }
        }
    };
    let out = gridscada_control::dispatch::solve_text(&text);
    if !out.stdout.is_empty() {
        println!("{}", out.stdout);
    }
    eprint!("{}", out.stderr);
    std::process::exit(out.exit_code);
}
