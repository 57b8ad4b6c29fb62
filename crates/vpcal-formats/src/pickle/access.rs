//! Accessors of [`Value`], and [`View`] whose errors name the path.

use std::borrow::Cow;

use super::decode::*;
use super::value::*;

impl Value {
    /// Python's name for the type, for messages (`numpy.ndarray[<f8]` for arrays).
    pub fn type_name(&self) -> Cow<'static, str> {
        Cow::Borrowed(match self {
            Value::None => "None",
            Value::Bool(_) => "bool",
            Value::Int(_) | Value::BigInt(_) => "int",
            Value::Float(_) => "float",
            Value::Str(_) => "str",
            Value::Bytes(_) | Value::Deferred(_) => "bytes",
            Value::List(_) => "list",
            Value::Tuple(_) => "tuple",
            Value::Dict(_) => "dict",
            Value::Set(_) => "set",
            Value::FrozenSet(_) => "frozenset",
            Value::Array(a) => return Cow::Owned(format!("numpy.ndarray[{}]", a.dtype.descr())),
            Value::Scalar(a) => return Cow::Owned(format!("numpy scalar {}", a.dtype.descr())),
        })
    }

    /// The value of `key` in a dict with str keys.
    pub fn get(&self, key: &str) -> Option<&Value> {
        match self {
            Value::Dict(pairs) => pairs
                .iter()
                .find(|(k, _)| matches!(k, Value::Str(s) if s == key))
                .map(|(_, v)| v),
            _ => None,
        }
    }

    /// The value of an integer key in a dict.
    pub fn get_int(&self, key: i64) -> Option<&Value> {
        match self {
            Value::Dict(pairs) => pairs
                .iter()
                .find(|(k, _)| k.as_i64() == Some(key) && !matches!(k, Value::Bool(_)))
                .map(|(_, v)| v),
            _ => None,
        }
    }

    /// Element `i` of a list, tuple or object array.
    pub fn at(&self, i: usize) -> Option<&Value> {
        match self {
            Value::List(v) | Value::Tuple(v) => v.get(i),
            Value::Array(a) => match &a.data {
                ArrayData::Object(v) => v.get(i),
                _ => None,
            },
            _ => None,
        }
    }

    /// Elements of a list or tuple.
    pub fn as_list(&self) -> Option<&[Value]> {
        match self {
            Value::List(v) | Value::Tuple(v) => Some(v),
            _ => None,
        }
    }

    /// Pairs of a dict.
    pub fn as_dict(&self) -> Option<&[(Value, Value)]> {
        match self {
            Value::Dict(v) => Some(v),
            _ => None,
        }
    }

    /// Elements of a set or frozenset.
    pub fn as_set(&self) -> Option<&[Value]> {
        match self {
            Value::Set(v) | Value::FrozenSet(v) => Some(v),
            _ => None,
        }
    }

    /// A number: float, int (within i64), or a numeric numpy scalar / one-element array.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Float(f) => Some(*f),
            Value::Int(i) => Some(*i as f64),
            Value::Scalar(a) | Value::Array(a) if a.data.len() == 1 => match a.dtype.kind {
                DtypeKind::Bool | DtypeKind::Object => None,
                _ => a.data.get_f64(0),
            },
            _ => None,
        }
    }

    /// An integer: int (or bool, which is an int in Python) or an integer numpy scalar.
    pub fn as_i64(&self) -> Option<i64> {
        match self {
            Value::Int(i) => Some(*i),
            Value::Bool(b) => Some(i64::from(*b)),
            Value::Scalar(a) => match a.dtype.kind {
                DtypeKind::Int | DtypeKind::UInt | DtypeKind::Bool => a.data.get_i64(0),
                _ => None,
            },
            _ => None,
        }
    }

    /// A bool or numpy bool scalar.
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(b) => Some(*b),
            Value::Scalar(a) => match &a.data {
                ArrayData::Bool(v) => v.first().copied(),
                _ => None,
            },
            _ => None,
        }
    }

    /// Text.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    /// Raw bytes: `bytes`, a Python-2 byte string (decoded as latin-1, re-encoded here), or a
    /// uint8/int8 numpy array (flattened).
    pub fn as_byte_string(&self) -> Option<Cow<'_, [u8]>> {
        match self {
            Value::Bytes(b) => Some(Cow::Borrowed(b)),
            Value::Str(s) => latin1_bytes(s).ok().map(Cow::Owned),
            Value::Array(a) => match &a.data {
                ArrayData::U8(v) => Some(Cow::Borrowed(v)),
                ArrayData::I8(v) => Some(Cow::Owned(v.iter().map(|&b| b as u8).collect())),
                _ => None,
            },
            _ => None,
        }
    }

    /// A numpy array (not a scalar).
    pub fn as_array(&self) -> Option<&NdArray> {
        match self {
            Value::Array(a) => Some(a.as_ref()),
            _ => None,
        }
    }

    /// A numeric numpy array (or scalar) as shape + f64 data in C order.
    pub fn as_array_f64(&self) -> Option<(Vec<usize>, Vec<f64>)> {
        match self {
            Value::Array(a) | Value::Scalar(a) => Some((a.shape.clone(), a.to_f64_vec()?)),
            _ => None,
        }
    }

    /// A [`View`] rooted here, whose accessors report the path in errors.
    pub fn view(&self) -> View<'_> {
        View {
            value: self,
            path: String::new(),
        }
    }

    /// A short description for error messages: the type and, for small values, the value.
    pub fn describe(&self) -> String {
        match self {
            Value::None => "None".into(),
            Value::Bool(b) => format!("bool {}", if *b { "True" } else { "False" }),
            Value::Int(i) => format!("int {i}"),
            Value::Float(f) => format!("float {f}"),
            Value::Str(s) if s.chars().count() <= 40 => format!("str {s:?}"),
            Value::Str(s) => format!("str of {} characters", s.chars().count()),
            Value::Bytes(b) => format!("bytes of length {}", b.len()),
            Value::List(v) => format!("list of {} items", v.len()),
            Value::Tuple(v) => format!("tuple of {} items", v.len()),
            Value::Dict(v) => format!("dict of {} items", v.len()),
            Value::Set(v) | Value::FrozenSet(v) => {
                format!("{} of {} items", self.type_name(), v.len())
            }
            Value::Array(a) => format!("numpy.ndarray {} of shape {:?}", a.dtype.descr(), a.shape),
            other => other.type_name().into_owned(),
        }
    }

    /// Decimal text of an integer (`Int` or `BigInt`), `None` for other values and, as Python's
    /// `str()`, for integers of more than about [`MAX_INT_DIGITS`] digits (the conversion is
    /// quadratic).
    pub fn to_decimal_string(&self) -> Option<String> {
        match self {
            Value::Int(i) => Some(i.to_string()),
            Value::BigInt(b) if b.len() <= MAX_BIGINT_BYTES_TO_DECIMAL => {
                Some(le_twos_complement_to_decimal(b))
            }
            _ => None,
        }
    }
}

/// Bytes of a two's-complement integer of [`MAX_INT_DIGITS`] decimal digits (4300 · log2(10) / 8).
const MAX_BIGINT_BYTES_TO_DECIMAL: usize = 1787;

fn le_twos_complement_to_decimal(bytes: &[u8]) -> String {
    let neg = bytes.last().is_some_and(|b| b & 0x80 != 0);
    let mut mag: Vec<u8> = bytes.to_vec();
    if neg {
        let mut carry = true;
        for b in mag.iter_mut() {
            let (v, c) = (!*b).overflowing_add(u8::from(carry));
            *b = v;
            carry = c;
        }
    }
    // Repeated division by 10^9 on big-endian u32 limbs.
    let mut limbs: Vec<u32> = mag
        .chunks(4)
        .map(|c| {
            let mut a = [0u8; 4];
            a[..c.len()].copy_from_slice(c);
            u32::from_le_bytes(a)
        })
        .rev()
        .collect();
    let mut parts: Vec<u32> = Vec::new();
    while limbs.iter().any(|&l| l != 0) {
        let mut rem = 0u64;
        for l in limbs.iter_mut() {
            let cur = (rem << 32) | u64::from(*l);
            *l = (cur / 1_000_000_000) as u32;
            rem = cur % 1_000_000_000;
        }
        parts.push(rem as u32);
    }
    let mut s = String::new();
    if neg {
        s.push('-');
    }
    match parts.split_last() {
        None => s.push('0'),
        Some((most, rest)) => {
            s.push_str(&most.to_string());
            for p in rest.iter().rev() {
                s.push_str(&format!("{p:09}"));
            }
        }
    }
    s
}

/// A [`Value`] with its path from the root, for accessors that return descriptive errors.
#[derive(Debug, Clone)]
pub struct View<'a> {
    pub value: &'a Value,
    path: String,
}

/// A value was missing or of the wrong type; names the path and what was found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("at {path}: expected {expected}, found {found}")]
pub struct AccessError {
    /// Python-like path from the root, e.g. `["cars"][3]["speed"]` (`<root>` for the root).
    pub path: String,
    pub expected: String,
    pub found: String,
}

impl<'a> View<'a> {
    /// Path from the root, e.g. `["cars"][3]["speed"]`.
    pub fn path(&self) -> &str {
        if self.path.is_empty() {
            "<root>"
        } else {
            &self.path
        }
    }

    fn err(&self, expected: impl Into<String>) -> AccessError {
        AccessError {
            path: self.path().to_string(),
            expected: expected.into(),
            found: self.value.describe(),
        }
    }

    fn check<T>(&self, v: Option<T>, expected: &str) -> Result<T, AccessError> {
        v.ok_or_else(|| self.err(expected))
    }

    /// The value of `key` in a dict with str keys.
    ///
    /// # Errors
    /// When this is not a dict or the key is absent.
    pub fn get(&self, key: &str) -> Result<View<'a>, AccessError> {
        let Value::Dict(_) = self.value else {
            return Err(self.err(format!("a dict with key {key:?}")));
        };
        match self.value.get(key) {
            Some(v) => Ok(View {
                value: v,
                path: format!("{}[{key:?}]", self.path),
            }),
            None => Err(self.err(format!("a dict with key {key:?}"))),
        }
    }

    /// The value of `key`, or `None` when the dict lacks it.
    ///
    /// # Errors
    /// When this is not a dict.
    pub fn get_opt(&self, key: &str) -> Result<Option<View<'a>>, AccessError> {
        let Value::Dict(_) = self.value else {
            return Err(self.err(format!("a dict (looking for key {key:?})")));
        };
        Ok(self.value.get(key).map(|v| View {
            value: v,
            path: format!("{}[{key:?}]", self.path),
        }))
    }

    /// The value of an integer key.
    ///
    /// # Errors
    /// When this is not a dict or the key is absent.
    pub fn get_int(&self, key: i64) -> Result<View<'a>, AccessError> {
        match self.value.get_int(key) {
            Some(v) => Ok(View {
                value: v,
                path: format!("{}[{key}]", self.path),
            }),
            None => Err(self.err(format!("a dict with key {key}"))),
        }
    }

    /// Element `i` of a list, tuple or object array.
    ///
    /// # Errors
    /// When this is not a sequence or `i` is out of range.
    pub fn at(&self, i: usize) -> Result<View<'a>, AccessError> {
        match self.value.at(i) {
            Some(v) => Ok(View {
                value: v,
                path: format!("{}[{i}]", self.path),
            }),
            None => Err(self.err(format!("a list with an element {i}"))),
        }
    }

    /// Elements of a list or tuple (or object array), each with its path.
    ///
    /// # Errors
    /// When this is not a sequence.
    pub fn items(&self) -> Result<Vec<View<'a>>, AccessError> {
        let items: &'a [Value] = match self.value {
            Value::List(v) | Value::Tuple(v) => v,
            Value::Array(a) => match &a.data {
                ArrayData::Object(v) => v,
                _ => return Err(self.err("a list")),
            },
            _ => return Err(self.err("a list")),
        };
        Ok(items
            .iter()
            .enumerate()
            .map(|(i, v)| View {
                value: v,
                path: format!("{}[{i}]", self.path),
            })
            .collect())
    }

    /// Key-value pairs of a dict, values with their paths.
    ///
    /// # Errors
    /// When this is not a dict.
    pub fn entries(&self) -> Result<Vec<(&'a Value, View<'a>)>, AccessError> {
        let Value::Dict(pairs) = self.value else {
            return Err(self.err("a dict"));
        };
        Ok(pairs
            .iter()
            .map(|(k, v)| {
                let seg = match k {
                    Value::Str(s) => format!("{s:?}"),
                    other => other
                        .to_decimal_string()
                        .unwrap_or_else(|| other.type_name().into_owned()),
                };
                (
                    k,
                    View {
                        value: v,
                        path: format!("{}[{seg}]", self.path),
                    },
                )
            })
            .collect())
    }

    /// See [`Value::as_f64`].
    ///
    /// # Errors
    /// When this is not a number.
    pub fn as_f64(&self) -> Result<f64, AccessError> {
        self.check(self.value.as_f64(), "a number")
    }

    /// See [`Value::as_i64`].
    ///
    /// # Errors
    /// When this is not an integer.
    pub fn as_i64(&self) -> Result<i64, AccessError> {
        self.check(self.value.as_i64(), "an integer")
    }

    /// See [`Value::as_bool`].
    ///
    /// # Errors
    /// When this is not a bool.
    pub fn as_bool(&self) -> Result<bool, AccessError> {
        self.check(self.value.as_bool(), "a bool")
    }

    /// See [`Value::as_str`].
    ///
    /// # Errors
    /// When this is not a str.
    pub fn as_str(&self) -> Result<&'a str, AccessError> {
        self.check(self.value.as_str(), "a str")
    }

    /// See [`Value::as_byte_string`].
    ///
    /// # Errors
    /// When this is not a byte string.
    pub fn as_byte_string(&self) -> Result<Cow<'a, [u8]>, AccessError> {
        self.check(self.value.as_byte_string(), "a byte string")
    }

    /// Elements of a set or frozenset.
    ///
    /// # Errors
    /// When this is not a set.
    pub fn as_set(&self) -> Result<&'a [Value], AccessError> {
        self.check(self.value.as_set(), "a set")
    }

    /// See [`Value::as_array_f64`].
    ///
    /// # Errors
    /// When this is not a numeric numpy array.
    pub fn as_array_f64(&self) -> Result<(Vec<usize>, Vec<f64>), AccessError> {
        self.check(self.value.as_array_f64(), "a numeric numpy array")
    }

    /// A numeric numpy array of exactly `N` elements (any shape with that many elements, e.g. a
    /// homogeneous point of shape (3,)).
    ///
    /// # Errors
    /// When this is not a numeric array of `N` elements.
    pub fn as_f64_array<const N: usize>(&self) -> Result<[f64; N], AccessError> {
        let expected = format!("a numeric numpy array of {N} elements");
        let (_, data) = self.check(self.value.as_array_f64(), &expected)?;
        <[f64; N]>::try_from(data).map_err(|_| self.err(expected))
    }
}
