//! `gridscada dispatch solve FILE`: solve a dispatch problem from JSON.
//!
//! **Owns:** reading the file (`-` = stdin), printing the answer (stdout) or
//! the error (stderr), and the exit code. **Must not touch:** the problem
//! itself: [`gridscada_control::dispatch::solve_text`] is the same solve as
//! the live outer loop.

use std::io::{Read, Write};

/// Solves the problem (or list of problems) in `path` and prints the JSON
/// answer. Returns the exit code: 0 optimal, 1 malformed input (or unreadable
/// file), 2 infeasible, 3 solver failure.
pub fn run_solve(path: &str) -> i32 {
    let text = if path == "-" {
        let mut s = String::new();
        match std::io::stdin().read_to_string(&mut s) {
            Ok(_) => s,
            Err(e) => {
                eprintln!("error: cannot read the problem from stdin: {e}");
                return 1;
            }
        }
    } else {
        match std::fs::read_to_string(path) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("error: cannot read {path}: {e}");
                return 1;
            }
        }
    };
    let out = gridscada_control::dispatch::solve_text(&text);
    if !out.stdout.is_empty() {
        let mut so = std::io::stdout().lock();
        let _ = writeln!(so, "{}", out.stdout);
        let _ = so.flush();
    }
    if !out.stderr.is_empty() {
        eprint!("{}", out.stderr);
    }
    out.exit_code
}
