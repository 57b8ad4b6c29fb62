//! Pickled values as [`Json`] values, so that one typed reader serves `gt_data.pkl` and its
//! JSON twin: lists, tuples and sets become arrays, dicts objects (with str or int keys),
//! numpy arrays nested arrays of their shape, numpy scalars numbers.

use crate::json::Json;
use crate::pickle::{ArrayData, NdArray, Value};

/// Convert a pickled value.
///
/// # Errors
/// A message naming the first value that has no JSON form (byte strings, dict keys that are
/// neither strings nor integers, deferred data).
pub fn to_json(v: &Value) -> Result<Json, String> {
    Ok(match v {
        Value::None => Json::Null,
        Value::Bool(b) => Json::Bool(*b),
        Value::Int(i) => Json::Number(*i as f64),
        Value::BigInt(_) => Json::Number(
            v.to_decimal_string()
                .and_then(|s| s.parse::<f64>().ok())
                .ok_or("an integer that does not fit a float")?,
        ),
        Value::Float(f) => Json::Number(*f),
        Value::Str(s) => Json::String(s.clone()),
        Value::Bytes(_) | Value::Deferred(_) => return Err("a byte string".into()),
        Value::List(items) | Value::Tuple(items) | Value::Set(items) | Value::FrozenSet(items) => {
            Json::Array(items.iter().map(to_json).collect::<Result<_, _>>()?)
        }
        Value::Dict(pairs) => Json::Object(
            pairs
                .iter()
                .map(|(k, v)| {
                    let key = match k {
                        Value::Str(s) => s.clone(),
                        Value::Int(i) => i.to_string(),
                        other => return Err(format!("a dict key {}", other.describe())),
                    };
                    Ok((key, to_json(v)?))
                })
                .collect::<Result<_, String>>()?,
        ),
        Value::Array(a) => array_to_json(a)?,
        Value::Scalar(a) => match &a.data {
            ArrayData::Bool(b) if b.len() == 1 => Json::Bool(b[0]),
            data => Json::Number(data.get_f64(0).ok_or("a numpy scalar without a value")?),
        },
    })
}

fn array_to_json(a: &NdArray) -> Result<Json, String> {
    let flat: Vec<Json> = match &a.data {
        ArrayData::Object(items) => items.iter().map(to_json).collect::<Result<_, _>>()?,
        ArrayData::Deferred { .. } => return Err("a numpy array left in the file".into()),
        data => (0..data.len())
            .map(|i| data.get_f64(i).map(Json::Number).ok_or("a numpy element"))
            .collect::<Result<_, _>>()?,
    };
    if flat.len() != a.element_count() {
        return Err(format!(
            "a numpy array of shape {:?} holding {} elements",
            a.shape,
            flat.len()
        ));
    }
    Ok(nest(&a.shape, &mut flat.into_iter()))
}

fn nest(shape: &[usize], items: &mut impl Iterator<Item = Json>) -> Json {
    match shape.split_first() {
        None => items.next().unwrap_or(Json::Null),
        Some((&n, rest)) => Json::Array((0..n).map(|_| nest(rest, items)).collect()),
    }
}
