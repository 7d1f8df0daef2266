//! Command-line flags whose values are a config option set ([`Choice`]): the same names as the
//! config file (serde's), offered and checked by clap.

use crate::choice::Choice;
use clap::builder::{PossibleValuesParser, TypedValueParser};
use serde::Serialize;

/// The config file's name of an option (`robust`, `least-moved`).
pub fn name<T: Serialize>(v: &T) -> String {
    serde_json::to_value(v).ok().and_then(|j| j.as_str().map(str::to_string)).unwrap_or_default()
}

/// A clap parser that accepts exactly `T`'s config names and lists them in `--help`.
pub fn parser<T: Choice + Serialize + Send + Sync>() -> impl TypedValueParser<Value = T> {
    // Built once per flag at start-up; clap keeps the names for the process's life.
    let names: Vec<&'static str> = T::ALL.iter().map(|v| &*Box::leak(name(v).into_boxed_str())).collect();
    PossibleValuesParser::new(names).map(|s: String| T::ALL.iter().copied().find(|v| name(v) == s).unwrap_or(T::ALL[0]))
}
