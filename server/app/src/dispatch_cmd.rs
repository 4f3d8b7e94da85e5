//! `gridscada dispatch solve FILE`: solve a dispatch problem from JSON.
//!
//! **Owns:** reading the file (`-` = stdin), printing the answer (stdout) or
//! the error (stderr), and the exit code. **Must not touch:** the problem
//! itself: [`gridscada_control::dispatch::solve_text`] is the same solve as
//! the live outer loop.

use std::io::{Read, Write};

use gridscada_control::dispatch::{too_large, MAX_INPUT_BYTES};

/// Solves the problem (or list of problems) in `path` and prints the JSON
/// answer. Returns the exit code: 0 optimal, 1 malformed input (or unreadable
/// file), 2 infeasible, 3 solver failure.
pub fn run_solve(path: &str) -> i32 {
    let read = if path == "-" {
        read_problem(std::io::stdin().lock(), "the problem from stdin")
    } else {
        std::fs::File::open(path)
            .map_err(|e| format!("cannot read {path}: {e}"))
            .and_then(|f| read_problem(f, path))
    };
    let text = match read {
        Ok(text) => text,
        Err(e) => {
            eprintln!("error: {e}");
            return 1;
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

/// Reads the problem's text, but never more than one byte past
/// [`MAX_INPUT_BYTES`]: a huge file or an endless stdin is refused unread.
fn read_problem(from: impl Read, what: &str) -> Result<String, String> {
    let mut bytes = Vec::new();
    from.take(MAX_INPUT_BYTES as u64 + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot read {what}: {e}"))?;
    if bytes.len() > MAX_INPUT_BYTES {
        return Err(too_large(None).to_string());
    }
    String::from_utf8(bytes).map_err(|e| format!("cannot read {what}: not UTF-8 text ({e})"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_endless_input_is_refused_at_the_byte_limit() {
        let e = read_problem(std::io::repeat(b' '), "stdin").unwrap_err();
        assert_eq!(
            e,
            "the input is more than 16777216 bytes; at most 16777216 bytes (16 MiB) are accepted"
        );
        let text = read_problem(&b"{\"dt_h\": 1}"[..], "stdin").unwrap();
        assert_eq!(text, "{\"dt_h\": 1}");
        assert!(read_problem(&[0xff, 0xfe][..], "p.json")
            .unwrap_err()
            .starts_with("cannot read p.json: not UTF-8 text"));
    }
}
