//! JSON numbers as the document writes them: f32 values in their shortest round-trip form, and
//! the check that no non-finite number slipped in as `null`.

use serde_json::{json, Value};

/// An f32 as a JSON number in its shortest round-trip form ("0.15", not
/// "0.15000000596046448", which is what widening to f64 prints): a reader parsing the text as
/// f32 gets the same value back.
pub(super) fn number(x: f32) -> Value {
    json!(x.to_string().parse::<f64>().unwrap_or(f64::from(x)))
}

/// [`number`] for each value, as a JSON array.
pub(super) fn numbers(values: &[f32]) -> Value {
    Value::Array(values.iter().map(|&x| number(x)).collect())
}

/// Whether `v` holds a `null` anywhere: serde_json writes a non-finite float as null.
pub(super) fn contains_null(v: &Value) -> bool {
    match v {
        Value::Null => true,
        Value::Array(items) => items.iter().any(contains_null),
        Value::Object(map) => map.values().any(contains_null),
        _ => false,
    }
}
