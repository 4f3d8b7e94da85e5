//! How big a problem's JSON text asks to be, counted before it is read.
//!
//! **Owns:** the input's byte limit and a first pass over the text that
//! counts every problem's units, periods and per-period forecast entries
//! without keeping any of them (serde's `IgnoredAny`), so that an oversized
//! problem is refused in one quick scan instead of after a JSON tree of
//! hundreds of megabytes and a validation quadratic in its units (200,000
//! units took 27 s and 209 MB). **Must not touch:** the values: anything
//! within the limits is read and checked by [`super::input`] and the
//! problem modules, which also report a wrong shape.

use std::fmt;

use serde::de::{DeserializeSeed, Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};

use super::horizon::periods_within_limit;
use super::input::{index, join, InputError};
use super::single::{bad, units_within_limit, MAX_UNITS};

/// Scalars where a problem, a list or an object was expected count as
/// nothing here; reading the problem reports the wrong type, located.
macro_rules! scalars_count_as {
    ($v:expr) => {
        fn visit_unit<E>(self) -> Result<Self::Value, E> {
            Ok($v)
        }
        fn visit_bool<E>(self, _: bool) -> Result<Self::Value, E> {
            Ok($v)
        }
        fn visit_i64<E>(self, _: i64) -> Result<Self::Value, E> {
            Ok($v)
        }
        fn visit_u64<E>(self, _: u64) -> Result<Self::Value, E> {
            Ok($v)
        }
        fn visit_f64<E>(self, _: f64) -> Result<Self::Value, E> {
            Ok($v)
        }
        fn visit_str<E>(self, _: &str) -> Result<Self::Value, E> {
            Ok($v)
        }
    };
}

/// Most bytes of JSON `gridscada dispatch solve` reads (one problem or a
/// batch): a week of 5-minute periods for a few dozen units is under 1 MB.
pub const MAX_INPUT_BYTES: usize = 16 * 1024 * 1024;

/// The error for a text longer than [`MAX_INPUT_BYTES`]; `bytes` is its
/// length, or `None` when reading stopped at the limit.
pub fn too_large(bytes: Option<usize>) -> InputError {
    let size = match bytes {
        Some(n) => format!("{n} bytes"),
        None => format!("more than {MAX_INPUT_BYTES} bytes"),
    };
    InputError::new(
        "",
        format!(
            "the input is {size}; at most {MAX_INPUT_BYTES} bytes ({} MiB) are accepted",
            MAX_INPUT_BYTES / (1024 * 1024)
        ),
    )
}

/// Checks the text's size and counts what each problem in it asks for. The
/// scan stops at the first problem over a limit; its error and a syntax
/// error are located in the text.
pub(crate) fn within_limits(text: &str) -> Result<(), InputError> {
    if text.len() > MAX_INPUT_BYTES {
        return Err(too_large(Some(text.len())));
    }
    let mut refused = None;
    let mut de = serde_json::Deserializer::from_str(text);
    let counted = de
        .deserialize_any(Document {
            refused: &mut refused,
        })
        .and_then(|()| de.end());
    match (refused, counted) {
        (Some(e), _) => Err(e.locate_in(text)),
        (None, Err(e)) => Err(super::input::syntax_error(&e)),
        (None, Ok(())) => Ok(()),
    }
}

/// Where the first problem over a limit is kept; the scan then stops.
type Refused<'r> = &'r mut Option<InputError>;

fn refuse<E: serde::de::Error>(refused: Refused, r: Result<(), InputError>) -> Result<(), E> {
    r.map_err(|e| {
        *refused = Some(e);
        E::custom("over a limit")
    })
}

/// The document: one problem (an object) or a batch (a list of them).
struct Document<'p> {
    refused: Refused<'p>,
}

impl<'de> Visitor<'de> for Document<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a dispatch problem or a list of them")
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<(), A::Error> {
        Problem {
            path: String::new(),
            refused: self.refused,
        }
        .visit_map(map)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let mut i = 0;
        while seq
            .next_element_seed(Problem {
                path: index("", i),
                refused: &mut *self.refused,
            })?
            .is_some()
        {
            i += 1;
        }
        Ok(())
    }

    scalars_count_as!(());
}

/// One problem at `path`: its unit lists and its periods are counted.
struct Problem<'p> {
    path: String,
    refused: Refused<'p>,
}

impl<'de> DeserializeSeed<'de> for Problem<'_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Problem<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a dispatch problem")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        // Per unit list, as JSON reading keeps the last of repeated keys.
        let mut units = [0usize; 4];
        let mut periods = None;
        while let Some(key) = map.next_key::<String>()? {
            let list = ["pv", "wind", "oil", "storage"]
                .iter()
                .position(|k| *k == key);
            if let Some(l) = list {
                units[l] = map.next_value_seed(Count(None))?;
            } else if key == "periods" {
                let path = join(&self.path, "periods");
                periods = Some((
                    map.next_value_seed(Count(Some((path.clone(), &mut *self.refused))))?,
                    path,
                ));
            } else {
                map.next_value::<IgnoredAny>()?;
            }
        }
        refuse(
            &mut *self.refused,
            units_within_limit(self.path, units.iter().sum()),
        )?;
        match periods {
            Some((n, path)) => refuse(self.refused, periods_within_limit(path, n)),
            None => Ok(()),
        }
    }

    // Not an object: reading it says so.
    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<(), A::Error> {
        IgnoredAny.visit_seq(seq).map(|_| ())
    }
    scalars_count_as!(());
}

/// Counts a list's items (0 for anything else). With a path, the items are
/// periods, whose forecast maps are counted too.
struct Count<'p>(Option<(String, Refused<'p>)>);

impl<'de> DeserializeSeed<'de> for Count<'_> {
    type Value = usize;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<usize, D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Count<'_> {
    type Value = usize;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a list")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<usize, A::Error> {
        let mut n = 0;
        match self.0 {
            None => {
                while seq.next_element::<IgnoredAny>()?.is_some() {
                    n += 1;
                }
            }
            Some((path, refused)) => {
                while seq
                    .next_element_seed(Period {
                        path: index(&path, n),
                        refused: &mut *refused,
                    })?
                    .is_some()
                {
                    n += 1;
                }
            }
        }
        Ok(n)
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<usize, A::Error> {
        IgnoredAny.visit_map(map).map(|_| 0)
    }
    scalars_count_as!(0);
}

/// One period: its forecast maps (`available_kw`, `running`) name units, so
/// neither may have more entries than a problem has units.
struct Period<'p> {
    path: String,
    refused: Refused<'p>,
}

impl<'de> DeserializeSeed<'de> for Period<'_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Period<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a period")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        while let Some(key) = map.next_key::<String>()? {
            if key == "available_kw" || key == "running" {
                let entries = map.next_value_seed(Entries)?;
                if entries > MAX_UNITS {
                    return refuse(
                        self.refused,
                        Err(bad(
                            join(&self.path, &key),
                            format!(
                                "{entries} entries; at most {MAX_UNITS} (one per unit) are accepted"
                            ),
                        )),
                    );
                }
            } else {
                map.next_value::<IgnoredAny>()?;
            }
        }
        Ok(())
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<(), A::Error> {
        IgnoredAny.visit_seq(seq).map(|_| ())
    }
    scalars_count_as!(());
}

/// Counts a map's entries (0 for anything else).
struct Entries;

impl<'de> DeserializeSeed<'de> for Entries {
    type Value = usize;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<usize, D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Entries {
    type Value = usize;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an object")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<usize, A::Error> {
        let mut n = 0;
        while map.next_entry::<IgnoredAny, IgnoredAny>()?.is_some() {
            n += 1;
        }
        Ok(n)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<usize, A::Error> {
        IgnoredAny.visit_seq(seq).map(|_| 0)
    }
    scalars_count_as!(0);
}
