//! Decoding helpers: integers, strings, dtypes and array elements.

use super::node::*;
use super::value::*;

pub(super) fn pairs_of(items: Vec<Id>) -> StepResult<Vec<(Id, Id)>> {
    if items.len() % 2 != 0 {
        return invalid(format!(
            "odd number of items ({}) for key-value pairs",
            items.len()
        ));
    }
    Ok(items.chunks_exact(2).map(|c| (c[0], c[1])).collect())
}

pub(super) fn parse_memo_key(line: &[u8]) -> StepResult<u64> {
    std::str::from_utf8(line)
        .ok()
        .and_then(|s| s.trim().parse::<u64>().ok())
        .ok_or_else(|| {
            ErrorKind::Invalid(format!(
                "memo key {:?} is not a non-negative integer",
                String::from_utf8_lossy(line)
            ))
        })
}

/// latin-1 decoding: every byte is the code point of the same value.
pub(super) fn latin1(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| char::from(b)).collect()
}

/// latin-1 encoding; fails on code points above U+00FF.
pub(super) fn latin1_bytes(s: &str) -> StepResult<Vec<u8>> {
    s.chars()
        .map(|c| u8::try_from(u32::from(c)))
        .collect::<Result<Vec<u8>, _>>()
        .or_else(|_| invalid("byte string holds a character above U+00FF (not latin-1)"))
}

/// An integer from little-endian two's-complement bytes (LONG1/LONG4).
pub(super) fn int_from_le(mut bytes: Vec<u8>) -> Node {
    // Shortest form: drop sign-extension bytes.
    while bytes.len() > 1 {
        let last = bytes[bytes.len() - 1];
        let prev_neg = bytes[bytes.len() - 2] & 0x80 != 0;
        if (last == 0 && !prev_neg) || (last == 0xff && prev_neg) {
            bytes.pop();
        } else {
            break;
        }
    }
    if bytes.is_empty() {
        return Node::Int(0);
    }
    if bytes.len() <= 8 {
        let neg = bytes[bytes.len() - 1] & 0x80 != 0;
        let mut buf = if neg { [0xffu8; 8] } else { [0u8; 8] };
        buf[..bytes.len()].copy_from_slice(&bytes);
        return Node::Int(i64::from_le_bytes(buf));
    }
    Node::BigInt(bytes)
}

/// Decimal text (`INT`, `LONG`) to an integer node.
pub(super) fn parse_decimal_int(line: &[u8]) -> StepResult<Node> {
    let text = std::str::from_utf8(line)
        .map_err(|_| ErrorKind::Invalid("integer argument is not ASCII".into()))?
        .trim();
    if let Ok(v) = text.parse::<i64>() {
        return Ok(Node::Int(v));
    }
    let (neg, digits) = match text.as_bytes() {
        [b'-', rest @ ..] => (true, rest),
        [b'+', rest @ ..] => (false, rest),
        rest => (false, rest),
    };
    if digits.is_empty() || !digits.iter().all(u8::is_ascii_digit) {
        return invalid(format!("integer argument {text:?} is not a decimal number"));
    }
    if digits.len() > MAX_INT_DIGITS {
        return Err(ErrorKind::Unsupported(format!(
            "integer with {} digits (limit {MAX_INT_DIGITS})",
            digits.len()
        )));
    }
    // Magnitude in base 2^32 limbs, little-endian.
    let mut limbs: Vec<u32> = vec![0];
    for &d in digits {
        let mut carry = u64::from(d - b'0');
        for limb in limbs.iter_mut() {
            let v = u64::from(*limb) * 10 + carry;
            *limb = v as u32;
            carry = v >> 32;
        }
        if carry > 0 {
            limbs.push(carry as u32);
        }
    }
    let mut bytes: Vec<u8> = limbs.iter().flat_map(|l| l.to_le_bytes()).collect();
    bytes.push(0); // room for the sign bit
    if neg {
        // two's complement: invert and add one
        let mut carry = true;
        for b in bytes.iter_mut() {
            let (v, c) = (!*b).overflowing_add(u8::from(carry));
            *b = v;
            carry = c;
        }
    }
    Ok(int_from_le(bytes))
}

/// The quoted `STRING` argument, unescaped like Python's `codecs.escape_decode`.
pub(super) fn unquote_string(line: &[u8]) -> StepResult<Vec<u8>> {
    let (Some(&first), Some(&last)) = (line.first(), line.last()) else {
        return invalid("the STRING opcode argument must be quoted");
    };
    if line.len() < 2 || first != last || !(first == b'\'' || first == b'"') {
        return invalid("the STRING opcode argument must be quoted");
    }
    let s = &line[1..line.len() - 1];
    let mut out = Vec::with_capacity(s.len());
    let mut i = 0;
    while i < s.len() {
        let c = s[i];
        i += 1;
        if c != b'\\' {
            out.push(c);
            continue;
        }
        let Some(&e) = s.get(i) else {
            return invalid("trailing \\ in STRING argument");
        };
        i += 1;
        match e {
            b'\n' => {}
            b'\\' => out.push(b'\\'),
            b'\'' => out.push(b'\''),
            b'"' => out.push(b'"'),
            b'b' => out.push(0x08),
            b'f' => out.push(0x0c),
            b't' => out.push(b'\t'),
            b'n' => out.push(b'\n'),
            b'r' => out.push(b'\r'),
            b'v' => out.push(0x0b),
            b'a' => out.push(0x07),
            b'0'..=b'7' => {
                let mut v = u32::from(e - b'0');
                for _ in 0..2 {
                    match s.get(i) {
                        Some(&d @ b'0'..=b'7') => {
                            v = v * 8 + u32::from(d - b'0');
                            i += 1;
                        }
                        _ => break,
                    }
                }
                out.push((v & 0xff) as u8);
            }
            b'x' => {
                let hex = s.get(i..i + 2).and_then(|h| {
                    std::str::from_utf8(h)
                        .ok()
                        .and_then(|h| u8::from_str_radix(h, 16).ok())
                });
                match hex {
                    Some(v) => {
                        out.push(v);
                        i += 2;
                    }
                    None => return invalid("invalid \\x escape in STRING argument"),
                }
            }
            other => {
                out.push(b'\\');
                out.push(other);
            }
        }
    }
    Ok(out)
}

/// `raw-unicode-escape` decoding (`UNICODE`): bytes are latin-1 except `\uXXXX`, `\UXXXXXXXX`.
pub(super) fn raw_unicode_escape_decode(line: &[u8]) -> StepResult<String> {
    let mut out = String::with_capacity(line.len());
    let mut i = 0;
    while i < line.len() {
        let c = line[i];
        i += 1;
        let digits = match (c, line.get(i)) {
            (b'\\', Some(b'u')) => 4,
            (b'\\', Some(b'U')) => 8,
            (b'\\', Some(&other)) => {
                // Like CPython: a backslash and the character after it are both literal.
                out.push('\\');
                out.push(char::from(other));
                i += 1;
                continue;
            }
            _ => {
                out.push(char::from(c));
                continue;
            }
        };
        i += 1;
        let code = line
            .get(i..i + digits)
            .and_then(|h| std::str::from_utf8(h).ok())
            .filter(|h| h.bytes().all(|b| b.is_ascii_hexdigit()))
            .and_then(|h| u32::from_str_radix(h, 16).ok());
        let Some(code) = code else {
            return invalid(format!(
                "truncated \\{} escape in UNICODE argument",
                if digits == 4 { 'u' } else { 'U' }
            ));
        };
        i += digits;
        match char::from_u32(code) {
            Some(ch) => out.push(ch),
            None => {
                return invalid(format!(
                    "UNICODE argument has code point U+{code:04X} (surrogate or out of range)"
                ))
            }
        }
    }
    Ok(out)
}

/// A numpy dtype descriptor such as `f8`, `<i4`, `|b1`, `O8`.
pub(super) fn parse_dtype(descr: &str) -> StepResult<Dtype> {
    let (big_endian, rest) = match descr.as_bytes().first() {
        Some(b'>') => (true, &descr[1..]),
        Some(b'<' | b'|' | b'=') => (false, &descr[1..]),
        _ => (false, descr),
    };
    let unsupported = || {
        Err(ErrorKind::Unsupported(format!(
            "numpy dtype {descr:?} (supported: f4 f8 i1-i8 u1-u8 b1 O)"
        )))
    };
    let mut chars = rest.chars();
    let Some(kind_char) = chars.next() else {
        return unsupported();
    };
    let size_text = chars.as_str();
    let size: Option<usize> = if size_text.is_empty() {
        None
    } else {
        match size_text.parse() {
            Ok(s) => Some(s),
            Err(_) => return unsupported(),
        }
    };
    let (kind, itemsize) = match (kind_char, size) {
        ('f', Some(s @ (4 | 8))) => (DtypeKind::Float, s),
        ('i', Some(s @ (1 | 2 | 4 | 8))) => (DtypeKind::Int, s),
        ('u', Some(s @ (1 | 2 | 4 | 8))) => (DtypeKind::UInt, s),
        ('b', Some(1)) | ('?', None) => (DtypeKind::Bool, 1),
        ('O', None | Some(4 | 8)) => (DtypeKind::Object, 8),
        _ => return unsupported(),
    };
    Ok(Dtype {
        kind,
        itemsize,
        big_endian,
    })
}

/// Decode `count` elements of `dtype` from raw bytes (length already checked by callers that
/// know the shape; checked again here).
pub(super) fn decode_elements(bytes: &[u8], dtype: Dtype, count: usize) -> StepResult<ArrayData> {
    let need = count.checked_mul(dtype.itemsize);
    if need != Some(bytes.len()) {
        return invalid(format!(
            "numpy data of dtype {} for {count} elements has {} bytes",
            dtype.descr(),
            bytes.len()
        ));
    }
    macro_rules! conv {
        ($variant:ident, $t:ty, $n:expr) => {
            ArrayData::$variant(
                bytes
                    .chunks_exact($n)
                    .map(|c| {
                        let mut a = [0u8; $n];
                        a.copy_from_slice(c);
                        if dtype.big_endian {
                            <$t>::from_be_bytes(a)
                        } else {
                            <$t>::from_le_bytes(a)
                        }
                    })
                    .collect(),
            )
        };
    }
    Ok(match (dtype.kind, dtype.itemsize) {
        (DtypeKind::Bool, _) => ArrayData::Bool(bytes.iter().map(|&b| b != 0).collect()),
        (DtypeKind::Int, 1) => ArrayData::I8(bytes.iter().map(|&b| b as i8).collect()),
        (DtypeKind::Int, 2) => conv!(I16, i16, 2),
        (DtypeKind::Int, 4) => conv!(I32, i32, 4),
        (DtypeKind::Int, 8) => conv!(I64, i64, 8),
        (DtypeKind::UInt, 1) => ArrayData::U8(bytes.to_vec()),
        (DtypeKind::UInt, 2) => conv!(U16, u16, 2),
        (DtypeKind::UInt, 4) => conv!(U32, u32, 4),
        (DtypeKind::UInt, 8) => conv!(U64, u64, 8),
        (DtypeKind::Float, 4) => conv!(F32, f32, 4),
        (DtypeKind::Float, 8) => conv!(F64, f64, 8),
        _ => {
            return Err(ErrorKind::Unsupported(format!(
                "numpy dtype {} as raw data",
                dtype.descr()
            )))
        }
    })
}

/// Reorder Fortran-order (column-major) elements into C order.
pub(super) fn fortran_to_c(data: ArrayData, shape: &[usize]) -> ArrayData {
    pub(super) fn permute<T: Clone>(v: Vec<T>, shape: &[usize]) -> Vec<T> {
        let n = v.len();
        if n == 0 {
            return v;
        }
        // Fortran strides (in elements): first axis fastest.
        let mut fstride = vec![1usize; shape.len()];
        for k in 1..shape.len() {
            fstride[k] = fstride[k - 1] * shape[k - 1];
        }
        let mut out = Vec::with_capacity(n);
        let mut idx = vec![0usize; shape.len()];
        for _ in 0..n {
            let src: usize = idx.iter().zip(&fstride).map(|(i, s)| i * s).sum();
            if let Some(x) = v.get(src) {
                out.push(x.clone());
            }
            // advance the C-order multi-index (last axis fastest)
            for k in (0..shape.len()).rev() {
                idx[k] += 1;
                if idx[k] < shape[k] {
                    break;
                }
                idx[k] = 0;
            }
        }
        out
    }
    match data {
        ArrayData::Bool(v) => ArrayData::Bool(permute(v, shape)),
        ArrayData::I8(v) => ArrayData::I8(permute(v, shape)),
        ArrayData::I16(v) => ArrayData::I16(permute(v, shape)),
        ArrayData::I32(v) => ArrayData::I32(permute(v, shape)),
        ArrayData::I64(v) => ArrayData::I64(permute(v, shape)),
        ArrayData::U8(v) => ArrayData::U8(permute(v, shape)),
        ArrayData::U16(v) => ArrayData::U16(permute(v, shape)),
        ArrayData::U32(v) => ArrayData::U32(permute(v, shape)),
        ArrayData::U64(v) => ArrayData::U64(permute(v, shape)),
        ArrayData::F32(v) => ArrayData::F32(permute(v, shape)),
        ArrayData::F64(v) => ArrayData::F64(permute(v, shape)),
        other => other,
    }
}
