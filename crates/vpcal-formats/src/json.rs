//! JSON with Python's non-standard number tokens.
//!
//! Python's `json.dump` writes `Infinity`, `-Infinity` and `NaN` for non-finite floats, and
//! the reference code's per-vehicle outputs contain them. `serde_json` refuses these tokens
//! (and its `Value` cannot hold a non-finite number), so this module has a small JSON value
//! type whose numbers are plain `f64`, a parser that accepts the three tokens, and a writer
//! that emits them back, so such files round-trip without loss.
//!
//! vpcal's own files are strict JSON ([`Json::to_strict_string`]): a non-finite number is
//! written as `null`, and [`Json::as_f64`] reads `null` back as NaN (unknown, or at infinity),
//! so strict parsers (browsers, Node, `jq`) read everything vpcal writes.
//!
//! Typed accessors ([`Json::field`], [`Json::as_f64`], [`Json::as_point`], ...) return
//! [`AccessError`]s that name what was expected and what was found; readers add the file and
//! the item.

use std::fmt::Write as _;

/// A JSON value; numbers are f64 and may be non-finite.
#[derive(Debug, Clone, PartialEq)]
pub enum Json {
    Null,
    Bool(bool),
    Number(f64),
    String(String),
    Array(Vec<Json>),
    /// Members in file order.
    Object(Vec<(String, Json)>),
}

/// A syntax error, with 1-based line and column.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}, column {column}: {message}")]
pub struct ParseError {
    pub line: usize,
    pub column: usize,
    pub message: String,
}

/// A value of the wrong shape: what was expected, what was found, and where (a path such as
/// `[12].vp1[0]`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: expected {expected}, found {found}")]
pub struct AccessError {
    pub path: String,
    pub expected: String,
    pub found: String,
}

/// Maximum nesting depth accepted by the parser.
pub const MAX_DEPTH: usize = 256;

/// Parse a JSON document that may contain `Infinity`, `-Infinity` and `NaN`.
///
/// # Errors
/// [`ParseError`] with the position of the first syntax error.
pub fn parse(text: &str) -> Result<Json, ParseError> {
    let mut p = Parser {
        bytes: text.as_bytes(),
        pos: 0,
    };
    p.skip_ws();
    let v = p.value(0)?;
    p.skip_ws();
    if p.pos != p.bytes.len() {
        return Err(p.error("unexpected text after the JSON value"));
    }
    Ok(v)
}

struct Parser<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl Parser<'_> {
    fn error(&self, message: &str) -> ParseError {
        let upto = &self.bytes[..self.pos.min(self.bytes.len())];
        let line = upto.iter().filter(|b| **b == b'\n').count() + 1;
        let column = upto.iter().rev().take_while(|b| **b != b'\n').count() + 1;
        ParseError {
            line,
            column,
            message: message.to_string(),
        }
    }

    fn skip_ws(&mut self) {
        while let Some(b) = self.bytes.get(self.pos) {
            if matches!(b, b' ' | b'\t' | b'\n' | b'\r') {
                self.pos += 1;
            } else {
                break;
            }
        }
    }

    fn eat(&mut self, lit: &str) -> bool {
        if self.bytes[self.pos..].starts_with(lit.as_bytes()) {
            self.pos += lit.len();
            true
        } else {
            false
        }
    }

    fn value(&mut self, depth: usize) -> Result<Json, ParseError> {
        if depth > MAX_DEPTH {
            return Err(self.error("nesting too deep"));
        }
        match self.bytes.get(self.pos) {
            None => Err(self.error("unexpected end of input")),
            Some(b'{') => self.object(depth),
            Some(b'[') => self.array(depth),
            Some(b'"') => self.string().map(Json::String),
            Some(b't') if self.eat("true") => Ok(Json::Bool(true)),
            Some(b'f') if self.eat("false") => Ok(Json::Bool(false)),
            Some(b'n') if self.eat("null") => Ok(Json::Null),
            Some(b'N') if self.eat("NaN") => Ok(Json::Number(f64::NAN)),
            Some(b'I') if self.eat("Infinity") => Ok(Json::Number(f64::INFINITY)),
            Some(b'-') if self.eat("-Infinity") => Ok(Json::Number(f64::NEG_INFINITY)),
            Some(b'-' | b'0'..=b'9') => self.number(),
            Some(_) => Err(self.error("expected a JSON value")),
        }
    }

    fn object(&mut self, depth: usize) -> Result<Json, ParseError> {
        self.pos += 1;
        let mut members = Vec::new();
        self.skip_ws();
        if self.eat("}") {
            return Ok(Json::Object(members));
        }
        loop {
            self.skip_ws();
            if self.bytes.get(self.pos) != Some(&b'"') {
                return Err(self.error("expected a string key"));
            }
            let key = self.string()?;
            self.skip_ws();
            if !self.eat(":") {
                return Err(self.error("expected ':'"));
            }
            self.skip_ws();
            let v = self.value(depth + 1)?;
            members.push((key, v));
            self.skip_ws();
            if self.eat(",") {
                continue;
            }
            if self.eat("}") {
                return Ok(Json::Object(members));
            }
            return Err(self.error("expected ',' or '}'"));
        }
    }

    fn array(&mut self, depth: usize) -> Result<Json, ParseError> {
        self.pos += 1;
        let mut items = Vec::new();
        self.skip_ws();
        if self.eat("]") {
            return Ok(Json::Array(items));
        }
        loop {
            self.skip_ws();
            items.push(self.value(depth + 1)?);
            self.skip_ws();
            if self.eat(",") {
                continue;
            }
            if self.eat("]") {
                return Ok(Json::Array(items));
            }
            return Err(self.error("expected ',' or ']'"));
        }
    }

    fn number(&mut self) -> Result<Json, ParseError> {
        let start = self.pos;
        if self.bytes.get(self.pos) == Some(&b'-') {
            self.pos += 1;
        }
        let digits = |p: &mut Parser| {
            let s = p.pos;
            while p.bytes.get(p.pos).is_some_and(u8::is_ascii_digit) {
                p.pos += 1;
            }
            p.pos > s
        };
        if !digits(self) {
            return Err(self.error("expected digits"));
        }
        if self.bytes.get(self.pos) == Some(&b'.') {
            self.pos += 1;
            if !digits(self) {
                return Err(self.error("expected digits after '.'"));
            }
        }
        if matches!(self.bytes.get(self.pos), Some(b'e' | b'E')) {
            self.pos += 1;
            if matches!(self.bytes.get(self.pos), Some(b'+' | b'-')) {
                self.pos += 1;
            }
            if !digits(self) {
                return Err(self.error("expected exponent digits"));
            }
        }
        // The slice is ASCII digits and signs only, so it is valid UTF-8.
        let text = std::str::from_utf8(&self.bytes[start..self.pos])
            .map_err(|_| self.error("invalid number"))?;
        text.parse::<f64>()
            .map(Json::Number)
            .map_err(|_| self.error("invalid number"))
    }

    fn string(&mut self) -> Result<String, ParseError> {
        self.pos += 1; // opening quote
        let mut out = String::new();
        loop {
            let start = self.pos;
            while let Some(&b) = self.bytes.get(self.pos) {
                if b == b'"' || b == b'\\' || b < 0x20 {
                    break;
                }
                self.pos += 1;
            }
            let chunk = std::str::from_utf8(&self.bytes[start..self.pos])
                .map_err(|_| self.error("invalid UTF-8 in string"))?;
            out.push_str(chunk);
            match self.bytes.get(self.pos) {
                None => return Err(self.error("unterminated string")),
                Some(b'"') => {
                    self.pos += 1;
                    return Ok(out);
                }
                Some(b'\\') => {
                    self.pos += 1;
                    let esc = *self
                        .bytes
                        .get(self.pos)
                        .ok_or_else(|| self.error("unterminated escape"))?;
                    self.pos += 1;
                    match esc {
                        b'"' => out.push('"'),
                        b'\\' => out.push('\\'),
                        b'/' => out.push('/'),
                        b'b' => out.push('\u{8}'),
                        b'f' => out.push('\u{c}'),
                        b'n' => out.push('\n'),
                        b'r' => out.push('\r'),
                        b't' => out.push('\t'),
                        b'u' => {
                            let hi = self.hex4()?;
                            let c = if (0xD800..0xDC00).contains(&hi) {
                                if !self.eat("\\u") {
                                    return Err(self.error("unpaired surrogate"));
                                }
                                let lo = self.hex4()?;
                                if !(0xDC00..0xE000).contains(&lo) {
                                    return Err(self.error("invalid low surrogate"));
                                }
                                char::from_u32(0x10000 + ((hi - 0xD800) << 10) + (lo - 0xDC00))
                            } else {
                                char::from_u32(hi)
                            };
                            out.push(c.ok_or_else(|| self.error("invalid \\u escape"))?);
                        }
                        _ => return Err(self.error("invalid escape")),
                    }
                }
                Some(_) => return Err(self.error("control character in string")),
            }
        }
    }

    fn hex4(&mut self) -> Result<u32, ParseError> {
        let s = self
            .bytes
            .get(self.pos..self.pos + 4)
            .and_then(|b| std::str::from_utf8(b).ok())
            .and_then(|s| u32::from_str_radix(s, 16).ok())
            .ok_or_else(|| self.error("expected 4 hex digits"))?;
        self.pos += 4;
        Ok(s)
    }
}

impl Json {
    /// A short description of the value's kind, for error messages.
    pub fn kind(&self) -> String {
        match self {
            Json::Null => "null".into(),
            Json::Bool(_) => "a boolean".into(),
            Json::Number(n) => format!("the number {n}"),
            Json::String(_) => "a string".into(),
            Json::Array(a) => format!("an array of {}", a.len()),
            Json::Object(_) => "an object".into(),
        }
    }

    fn expected(&self, path: &str, expected: &str) -> AccessError {
        AccessError {
            path: if path.is_empty() {
                "$".into()
            } else {
                path.into()
            },
            expected: expected.into(),
            found: self.kind(),
        }
    }

    /// Member `key` of an object, if present.
    pub fn get(&self, key: &str) -> Option<&Json> {
        match self {
            Json::Object(m) => m.iter().find(|(k, _)| k == key).map(|(_, v)| v),
            _ => None,
        }
    }

    /// Member `key` of an object at `path`.
    ///
    /// # Errors
    /// When `self` is not an object or has no such member.
    pub fn field(&self, path: &str, key: &str) -> Result<&Json, AccessError> {
        match self {
            Json::Object(_) => self.get(key).ok_or_else(|| AccessError {
                path: format!("{path}.{key}"),
                expected: "a value".into(),
                found: "no such field".into(),
            }),
            _ => Err(self.expected(path, "an object")),
        }
    }

    /// The items of an array at `path`.
    ///
    /// # Errors
    /// When `self` is not an array.
    pub fn as_array(&self, path: &str) -> Result<&[Json], AccessError> {
        match self {
            Json::Array(a) => Ok(a),
            _ => Err(self.expected(path, "an array")),
        }
    }

    /// A number (possibly non-finite) at `path`; `null`, the strict-JSON spelling of a
    /// non-finite number, reads as NaN.
    ///
    /// # Errors
    /// When `self` is neither a number nor `null`.
    pub fn as_f64(&self, path: &str) -> Result<f64, AccessError> {
        match self {
            Json::Number(n) => Ok(*n),
            Json::Null => Ok(f64::NAN),
            _ => Err(self.expected(path, "a number")),
        }
    }

    /// A string at `path`.
    ///
    /// # Errors
    /// When `self` is not a string.
    pub fn as_str(&self, path: &str) -> Result<&str, AccessError> {
        match self {
            Json::String(s) => Ok(s),
            _ => Err(self.expected(path, "a string")),
        }
    }

    /// A boolean at `path`.
    ///
    /// # Errors
    /// When `self` is not a boolean.
    pub fn as_bool(&self, path: &str) -> Result<bool, AccessError> {
        match self {
            Json::Bool(b) => Ok(*b),
            _ => Err(self.expected(path, "a boolean")),
        }
    }

    /// An array of exactly `N` numbers at `path`.
    ///
    /// # Errors
    /// When `self` is not an array of `N` numbers.
    pub fn as_f64_array<const N: usize>(&self, path: &str) -> Result<[f64; N], AccessError> {
        let items = match self {
            Json::Array(a) if a.len() == N => a,
            _ => return Err(self.expected(path, &format!("an array of {N} numbers"))),
        };
        let mut out = [0.0; N];
        for (i, (o, item)) in out.iter_mut().zip(items).enumerate() {
            *o = item.as_f64(&format!("{path}[{i}]"))?;
        }
        Ok(out)
    }

    /// An array of numbers of any length at `path`.
    ///
    /// # Errors
    /// When `self` is not an array of numbers.
    pub fn as_f64_vec(&self, path: &str) -> Result<Vec<f64>, AccessError> {
        self.as_array(path)?
            .iter()
            .enumerate()
            .map(|(i, v)| v.as_f64(&format!("{path}[{i}]")))
            .collect()
    }

    /// A point `[x, y]` at `path`.
    ///
    /// # Errors
    /// When `self` is not an array of 2 numbers.
    pub fn as_point(&self, path: &str) -> Result<vpcal_geom::Point2, AccessError> {
        self.as_f64_array::<2>(path).map(vpcal_geom::Point2::from)
    }

    /// Serialise compactly, like Python's `json.dumps` (`", "` and `": "` separators), writing
    /// non-finite numbers as `Infinity`, `-Infinity` and `NaN`.
    pub fn to_python_string(&self) -> String {
        let mut out = String::new();
        self.write_python(&mut out, false);
        out
    }

    /// Serialise like [`Json::to_python_string`] but as strict JSON: non-finite numbers are
    /// written as `null` (what vpcal writes to its files).
    pub fn to_strict_string(&self) -> String {
        let mut out = String::new();
        self.write_python(&mut out, true);
        out
    }

    fn write_python(&self, out: &mut String, strict: bool) {
        match self {
            Json::Null => out.push_str("null"),
            Json::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
            Json::Number(n) if strict && !n.is_finite() => out.push_str("null"),
            Json::Number(n) => write_number(out, *n),
            Json::String(s) => write_string(out, s),
            Json::Array(items) => {
                out.push('[');
                for (i, v) in items.iter().enumerate() {
                    if i > 0 {
                        out.push_str(", ");
                    }
                    v.write_python(out, strict);
                }
                out.push(']');
            }
            Json::Object(members) => {
                out.push('{');
                for (i, (k, v)) in members.iter().enumerate() {
                    if i > 0 {
                        out.push_str(", ");
                    }
                    write_string(out, k);
                    out.push_str(": ");
                    v.write_python(out, strict);
                }
                out.push('}');
            }
        }
    }
}

/// Shorthand for building number arrays when writing.
impl From<&[f64]> for Json {
    fn from(v: &[f64]) -> Json {
        Json::Array(v.iter().map(|x| Json::Number(*x)).collect())
    }
}

impl From<f64> for Json {
    fn from(v: f64) -> Json {
        Json::Number(v)
    }
}

impl From<vpcal_geom::Point2> for Json {
    fn from(p: vpcal_geom::Point2) -> Json {
        Json::Array(vec![Json::Number(p.x), Json::Number(p.y)])
    }
}

fn write_number(out: &mut String, n: f64) {
    if n.is_nan() {
        out.push_str("NaN");
    } else if n == f64::INFINITY {
        out.push_str("Infinity");
    } else if n == f64::NEG_INFINITY {
        out.push_str("-Infinity");
    } else {
        // Debug gives the shortest representation that round-trips, with an exponent for
        // very large and small magnitudes, and always a '.' or exponent for floats.
        let _ = write!(out, "{n:?}");
    }
}

fn write_string(out: &mut String, s: &str) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn python_tokens_parse_and_round_trip() {
        let v = parse(
            r#"{"a": [Infinity, -Infinity, NaN, 1.5e3, -0.0], "b": "x\"y\u00e9", "c": null}"#,
        )
        .unwrap();
        let a = v.field("", "a").unwrap().as_f64_vec("a").unwrap();
        assert_eq!(a[0], f64::INFINITY);
        assert_eq!(a[1], f64::NEG_INFINITY);
        assert!(a[2].is_nan());
        assert_eq!(a[3], 1500.0);
        assert_eq!(v.get("b"), Some(&Json::String("x\"yé".into())));
        let text = v.to_python_string();
        assert_eq!(
            text,
            r#"{"a": [Infinity, -Infinity, NaN, 1500.0, -0.0], "b": "x\"yé", "c": null}"#
        );
        let again = parse(&text).unwrap();
        assert_eq!(again.to_python_string(), text);
    }

    #[test]
    fn strict_output_writes_null_and_reads_back_as_nan() {
        let v = Json::Array(vec![
            Json::Number(f64::INFINITY),
            Json::Number(f64::NAN),
            Json::Number(-2.5),
        ]);
        let text = v.to_strict_string();
        assert_eq!(text, "[null, null, -2.5]");
        let back = parse(&text).unwrap().as_f64_vec("").unwrap();
        assert!(back[0].is_nan() && back[1].is_nan());
        assert_eq!(back[2], -2.5);
        // serde_json, a strict parser, reads it.
        assert!(serde_json::from_str::<serde_json::Value>(&text).is_ok());
    }

    #[test]
    fn errors_say_where_and_what() {
        let e = parse("[1, 2,\n  oops]").unwrap_err();
        assert_eq!((e.line, e.column), (2, 3));
        let v = parse(r#"[{"vp1": [1, "x"]}]"#).unwrap();
        let item = &v.as_array("").unwrap()[0];
        let err = item
            .field("[0]", "vp1")
            .unwrap()
            .as_point("[0].vp1")
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "[0].vp1[1]: expected a number, found a string"
        );
        let err = item.field("[0]", "vp2").unwrap_err();
        assert_eq!(
            err.to_string(),
            "[0].vp2: expected a value, found no such field"
        );
        assert!(parse("").is_err());
        assert!(parse("[1] x").is_err());
        assert!(parse("[Inf]").is_err());
        assert!(parse(&"[".repeat(MAX_DEPTH + 2)).is_err());
    }

    proptest! {
        #[test]
        fn numbers_round_trip_bit_exactly(x in any::<f64>()) {
            let text = Json::Array(vec![Json::Number(x)]).to_python_string();
            let back = parse(&text).unwrap().as_f64_vec("").unwrap()[0];
            if x.is_nan() {
                prop_assert!(back.is_nan());
            } else {
                prop_assert_eq!(back.to_bits(), x.to_bits());
            }
        }

        #[test]
        fn arbitrary_text_never_panics(s in "\\PC{0,64}") {
            let _ = parse(&s);
        }
    }
}
