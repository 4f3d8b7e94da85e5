//! Reading dispatch problems from untrusted JSON.
//!
//! **Owns:** typed extraction from a parsed `serde_json::Value` with a field
//! path for every error (`storage[0].eff_charge`), and finding the line and
//! column of that path in the original text, so an engineer can go straight to
//! the bad field.
//!
//! **Must not touch:** the meaning of the fields; the problem modules decide
//! which fields exist and which values are valid.

use std::fmt;

use serde_json::{Map, Value};

/// A malformed-input error: where (field path, and line/column when the
/// problem came from text) and what.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InputError {
    /// Field path, e.g. `storage[0].eff_charge`; empty for the whole document.
    pub path: String,
    pub message: String,
    /// 1-based line and column in the JSON text, when known.
    pub line: Option<usize>,
    pub column: Option<usize>,
    /// Further problems found beside this one (validation reports them all).
    pub more: Vec<InputError>,
}

impl InputError {
    pub fn new(path: impl Into<String>, message: impl Into<String>) -> Self {
        InputError {
            path: path.into(),
            message: message.into(),
            line: None,
            column: None,
            more: Vec::new(),
        }
    }

    /// Every problem, this one first.
    pub fn all(&self) -> impl Iterator<Item = &InputError> {
        std::iter::once(self).chain(self.more.iter())
    }

    /// Adds the line and column of the path, found in `text`.
    pub(crate) fn locate_in(mut self, text: &str) -> Self {
        // The whole document has no place worth naming.
        if self.line.is_none() && !self.path.is_empty() {
            if let Some((l, c)) = locate(text, &self.path) {
                self.line = Some(l);
                self.column = Some(c);
            }
        }
        self.more = std::mem::take(&mut self.more)
            .into_iter()
            .map(|e| e.locate_in(text))
            .collect();
        self
    }
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.path.is_empty() {
            f.write_str(&self.message)?;
        } else {
            write!(f, "{}: {}", self.path, self.message)?;
        }
        if let (Some(l), Some(c)) = (self.line, self.column) {
            write!(f, " (line {l}, column {c})")?;
        }
        // Further problems, one per line, each as `error: ...` like the first
        // (the CLI prefixes the first).
        for e in &self.more {
            write!(f, "\nerror: {e}")?;
        }
        Ok(())
    }
}

/// Collects every problem of a validation instead of stopping at the first.
#[derive(Default)]
pub(crate) struct Problems(Vec<InputError>);

impl Problems {
    pub(crate) fn check(&mut self, r: Result<(), InputError>) {
        if let Err(e) = r {
            self.0.extend(e.all().map(|x| InputError {
                more: Vec::new(),
                ..x.clone()
            }));
        }
    }

    /// The first [`MAX_REPORTED`] problems, and how many more there are.
    pub(crate) fn finish(self) -> Result<(), InputError> {
        let total = self.0.len();
        let mut it = self.0.into_iter();
        match it.next() {
            None => Ok(()),
            Some(mut first) => {
                first.more = it.take(MAX_REPORTED - 1).collect();
                if total > MAX_REPORTED {
                    first.more.push(InputError::new(
                        "",
                        format!(
                            "{} more problems not shown (at most {MAX_REPORTED} are reported)",
                            total - MAX_REPORTED
                        ),
                    ));
                }
                Err(first)
            }
        }
    }
}

/// Most problems reported at once: each is located by a scan of the text,
/// so 10,000 bad periods would take minutes, and a screenful is enough to
/// start fixing.
pub(crate) const MAX_REPORTED: usize = 20;

impl std::error::Error for InputError {}

/// Parses JSON text, turning a syntax error into a located [`InputError`].
/// JSON has no NaN or infinity, so those are syntax errors here.
pub(crate) fn parse(text: &str) -> Result<Value, InputError> {
    serde_json::from_str(text).map_err(|e| syntax_error(&e))
}

/// A JSON syntax error, at its line and column.
pub(crate) fn syntax_error(e: &serde_json::Error) -> InputError {
    InputError {
        path: String::new(),
        message: format!("invalid JSON: {e}"),
        line: Some(e.line()),
        column: Some(e.column()),
        more: Vec::new(),
    }
}

pub(crate) fn join(path: &str, key: &str) -> String {
    if path.is_empty() {
        key.to_string()
    } else {
        format!("{path}.{key}")
    }
}

pub(crate) fn index(path: &str, i: usize) -> String {
    format!("{path}[{i}]")
}

/// A JSON object being read; remembers its path and which keys were used so
/// that unknown (misspelt) keys are reported instead of silently ignored.
pub(crate) struct Obj<'a> {
    pub path: String,
    map: &'a Map<String, Value>,
    known: Vec<&'static str>,
}

impl<'a> Obj<'a> {
    pub fn new(v: &'a Value, path: &str) -> Result<Self, InputError> {
        match v {
            Value::Object(map) => Ok(Obj {
                path: path.to_string(),
                map,
                known: Vec::new(),
            }),
            other => Err(InputError::new(
                path,
                format!("expected an object, found {}", kind(other)),
            )),
        }
    }

    fn get(&mut self, key: &'static str) -> Option<&'a Value> {
        self.known.push(key);
        self.map.get(key).filter(|v| !v.is_null())
    }

    fn missing(&self, key: &str) -> InputError {
        InputError::new(join(&self.path, key), "missing field")
    }

    pub fn opt_num(&mut self, key: &'static str) -> Result<Option<f64>, InputError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::Number(n)) => match n.as_f64() {
                Some(x) if x.is_finite() => Ok(Some(x)),
                _ => Err(InputError::new(
                    join(&self.path, key),
                    format!("{n} is not a finite number"),
                )),
            },
            Some(other) => Err(InputError::new(
                join(&self.path, key),
                format!("expected a number, found {}", kind(other)),
            )),
        }
    }

    pub fn num(&mut self, key: &'static str) -> Result<f64, InputError> {
        self.opt_num(key)?.ok_or_else(|| self.missing(key))
    }

    pub fn opt_bool(&mut self, key: &'static str) -> Result<Option<bool>, InputError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::Bool(b)) => Ok(Some(*b)),
            Some(other) => Err(InputError::new(
                join(&self.path, key),
                format!("expected true or false, found {}", kind(other)),
            )),
        }
    }

    pub fn bool(&mut self, key: &'static str) -> Result<bool, InputError> {
        self.opt_bool(key)?.ok_or_else(|| self.missing(key))
    }

    pub fn string(&mut self, key: &'static str) -> Result<String, InputError> {
        match self.get(key) {
            None => Err(self.missing(key)),
            Some(Value::String(s)) => Ok(s.clone()),
            Some(other) => Err(InputError::new(
                join(&self.path, key),
                format!("expected a string, found {}", kind(other)),
            )),
        }
    }

    /// An array field; a missing list is an error unless `optional`.
    pub fn list(
        &mut self,
        key: &'static str,
        optional: bool,
    ) -> Result<(String, &'a [Value]), InputError> {
        let path = join(&self.path, key);
        match self.get(key) {
            None if optional => Ok((path, &[])),
            None => Err(self.missing(key)),
            Some(Value::Array(a)) => Ok((path, a.as_slice())),
            Some(other) => Err(InputError::new(
                path,
                format!("expected a list, found {}", kind(other)),
            )),
        }
    }

    pub fn opt_obj(&mut self, key: &'static str) -> Result<Option<Obj<'a>>, InputError> {
        let path = join(&self.path, key);
        match self.get(key) {
            None => Ok(None),
            Some(v) => Obj::new(v, &path).map(Some),
        }
    }

    /// The object's entries as (key, value) pairs, for maps keyed by unit id.
    pub fn entries(&self) -> impl Iterator<Item = (&'a String, &'a Value)> {
        self.map.iter()
    }

    /// Fails on any key not read so far.
    pub fn finish(self) -> Result<(), InputError> {
        for key in self.map.keys() {
            if !self.known.iter().any(|k| k == key) {
                return Err(InputError::new(join(&self.path, key), "unknown field"));
            }
        }
        Ok(())
    }
}

pub(crate) fn kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "an object",
    }
}

/// Line and column (1-based) of the value at `path` (`a.b[2].c`) in valid
/// JSON `text`; for a key that is missing, the position of the object that
/// should hold it. `None` if the text does not have that shape.
pub(crate) fn locate(text: &str, path: &str) -> Option<(usize, usize)> {
    let bytes = text.as_bytes();
    let mut pos = skip_ws(bytes, 0);
    let mut rest = path;
    loop {
        if rest.is_empty() {
            break;
        }
        if let Some(r) = rest.strip_prefix('[') {
            let end = r.find(']')?;
            let idx: usize = r[..end].parse().ok()?;
            rest = &r[end + 1..];
            if bytes.get(pos) != Some(&b'[') {
                return None;
            }
            let mut p = skip_ws(bytes, pos + 1);
            for _ in 0..idx {
                p = skip_value(bytes, p)?;
                p = skip_ws(bytes, p);
                if bytes.get(p) != Some(&b',') {
                    return None;
                }
                p = skip_ws(bytes, p + 1);
            }
            pos = p;
        } else {
            let r = rest.strip_prefix('.').unwrap_or(rest);
            let end = r.find(['.', '[']).unwrap_or(r.len());
            let key = &r[..end];
            rest = &r[end..];
            if bytes.get(pos) != Some(&b'{') {
                return None;
            }
            let object_pos = pos;
            let mut p = skip_ws(bytes, pos + 1);
            let mut found = false;
            while bytes.get(p) == Some(&b'"') {
                let kend = skip_string(bytes, p)?;
                let k: String = serde_json::from_str(&text[p..kend]).ok()?;
                p = skip_ws(bytes, kend);
                if bytes.get(p) != Some(&b':') {
                    return None;
                }
                p = skip_ws(bytes, p + 1);
                if k == key {
                    found = true;
                    break;
                }
                p = skip_ws(bytes, skip_value(bytes, p)?);
                if bytes.get(p) == Some(&b',') {
                    p = skip_ws(bytes, p + 1);
                }
            }
            if !found {
                pos = object_pos;
                break;
            }
            pos = p;
        }
    }
    let before = &text[..pos.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    Some((line, col))
}

fn skip_ws(b: &[u8], mut p: usize) -> usize {
    while p < b.len() && matches!(b[p], b' ' | b'\t' | b'\n' | b'\r') {
        p += 1;
    }
    p
}

/// Position just after the string starting at `p` (which is `"`).
fn skip_string(b: &[u8], p: usize) -> Option<usize> {
    let mut i = p + 1;
    while i < b.len() {
        match b[i] {
            b'\\' => i += 2,
            b'"' => return Some(i + 1),
            _ => i += 1,
        }
    }
    None
}

/// Position just after the value starting at `p`.
fn skip_value(b: &[u8], p: usize) -> Option<usize> {
    match b.get(p)? {
        b'"' => skip_string(b, p),
        b'{' | b'[' => {
            let mut depth = 0usize;
            let mut i = p;
            while i < b.len() {
                match b[i] {
                    b'"' => {
                        i = skip_string(b, i)?;
                        continue;
                    }
                    b'{' | b'[' => depth += 1,
                    b'}' | b']' => {
                        depth -= 1;
                        if depth == 0 {
                            return Some(i + 1);
                        }
                    }
                    _ => {}
                }
                i += 1;
            }
            None
        }
        _ => {
            let mut i = p;
            while i < b.len() && !matches!(b[i], b',' | b'}' | b']' | b' ' | b'\t' | b'\n' | b'\r')
            {
                i += 1;
            }
            Some(i)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locates_nested_fields() {
        let text = "{\n  \"a\": 1,\n  \"storage\": [\n    {\"id\": \"x\"},\n    {\"id\": \"y\", \"eff\": 1.2}\n  ]\n}";
        assert_eq!(locate(text, "a"), Some((2, 8)));
        assert_eq!(locate(text, "storage[1].eff"), Some((5, 24)));
        // A missing key points at its object.
        assert_eq!(locate(text, "storage[0].eff"), Some((4, 5)));
        assert_eq!(locate(text, "storage[7].eff"), None);
    }

    #[test]
    fn syntax_errors_carry_line_and_column() {
        let e = parse("{\"a\": NaN}").unwrap_err();
        assert_eq!(e.line, Some(1));
        assert!(e.message.contains("invalid JSON"));
    }
}
