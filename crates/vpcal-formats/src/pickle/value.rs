//! The values a pickle rebuilds (numpy arrays included), the load options and the errors.

use std::borrow::Cow;
use std::fmt;
use std::hash::Hash;
use std::io::{self, Read};
use std::path::PathBuf;

/// Deepest nesting of containers accepted in the result.
pub const MAX_DEPTH: usize = 200;
/// Longest decimal integer accepted in text opcodes (`INT`, `LONG`), as in Python's own limit.
pub const MAX_INT_DIGITS: usize = 4300;
/// Highest pickle protocol understood (protocol 5 adds out-of-band buffers, not supported).
pub const MAX_PROTOCOL: u8 = 4;

// ---------------------------------------------------------------------------------------------
// Public data model
// ---------------------------------------------------------------------------------------------

/// A value rebuilt from a pickle.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    None,
    Bool(bool),
    Int(i64),
    /// An integer outside `i64`: little-endian two's-complement bytes, shortest form.
    BigInt(Vec<u8>),
    Float(f64),
    /// Unicode text; Python-2 byte strings arrive here decoded as latin-1.
    Str(String),
    Bytes(Vec<u8>),
    /// A byte string left in the input (see [`LoadOptions::defer_bytes_over`]).
    Deferred(ByteSpan),
    List(Vec<Value>),
    Tuple(Vec<Value>),
    /// Key-value pairs in insertion order.
    Dict(Vec<(Value, Value)>),
    Set(Vec<Value>),
    FrozenSet(Vec<Value>),
    /// A numpy array (boxed: it is the largest variant).
    Array(Box<NdArray>),
    /// A numpy scalar (`numpy.float64(1.5)` and the like): an [`NdArray`] with an empty shape.
    Scalar(Box<NdArray>),
}

/// A byte range of the input, `offset` counted from where reading started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ByteSpan {
    pub offset: u64,
    pub len: u64,
}

impl ByteSpan {
    /// Read this span from a seekable reader positioned anywhere.
    ///
    /// # Errors
    /// I/O errors, including `UnexpectedEof` when the file is shorter than the span.
    pub fn read_from<R: Read + io::Seek>(&self, reader: &mut R) -> io::Result<Vec<u8>> {
        reader.seek(io::SeekFrom::Start(self.offset))?;
        let mut out = Vec::new();
        reader.take(self.len).read_to_end(&mut out)?;
        if out.len() as u64 != self.len {
            return Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                format!(
                    "byte span {}+{} runs past the end of the file",
                    self.offset, self.len
                ),
            ));
        }
        Ok(out)
    }
}

/// The element type of a numpy array.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Dtype {
    pub kind: DtypeKind,
    /// Bytes per element (1 for bool, 8 for object arrays on 64-bit platforms).
    pub itemsize: usize,
    /// Byte order of the data in the file (the decoded data is native).
    pub big_endian: bool,
}

/// numpy's dtype `kind` character.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DtypeKind {
    /// `b`
    Bool,
    /// `i`
    Int,
    /// `u`
    UInt,
    /// `f`
    Float,
    /// `O`
    Object,
}

impl Dtype {
    /// numpy's short name, e.g. `<f8`, `|u1`, `|O`.
    pub fn descr(&self) -> String {
        let kind = match self.kind {
            DtypeKind::Bool => 'b',
            DtypeKind::Int => 'i',
            DtypeKind::UInt => 'u',
            DtypeKind::Float => 'f',
            DtypeKind::Object => return "|O".to_string(),
        };
        let order = if self.itemsize == 1 {
            '|'
        } else if self.big_endian {
            '>'
        } else {
            '<'
        };
        format!("{order}{kind}{}", self.itemsize)
    }
}

/// A numpy array (or scalar, with an empty shape), C order, native values.
#[derive(Debug, Clone, PartialEq)]
pub struct NdArray {
    pub shape: Vec<usize>,
    pub dtype: Dtype,
    pub data: ArrayData,
}

/// Element storage of an [`NdArray`], row-major.
#[derive(Debug, Clone, PartialEq)]
pub enum ArrayData {
    Bool(Vec<bool>),
    I8(Vec<i8>),
    I16(Vec<i16>),
    I32(Vec<i32>),
    I64(Vec<i64>),
    U8(Vec<u8>),
    U16(Vec<u16>),
    U32(Vec<u32>),
    U64(Vec<u64>),
    F32(Vec<f32>),
    F64(Vec<f64>),
    Object(Vec<Value>),
    /// The raw bytes were left in the file (see [`LoadOptions::defer_bytes_over`]): their
    /// layout is the file's (`dtype` byte order, and C order unless the array was Fortran).
    Deferred {
        span: ByteSpan,
        fortran_order: bool,
    },
}

impl ArrayData {
    /// Number of elements held (0 for deferred data).
    pub fn len(&self) -> usize {
        match self {
            ArrayData::Bool(v) => v.len(),
            ArrayData::I8(v) => v.len(),
            ArrayData::I16(v) => v.len(),
            ArrayData::I32(v) => v.len(),
            ArrayData::I64(v) => v.len(),
            ArrayData::U8(v) => v.len(),
            ArrayData::U16(v) => v.len(),
            ArrayData::U32(v) => v.len(),
            ArrayData::U64(v) => v.len(),
            ArrayData::F32(v) => v.len(),
            ArrayData::F64(v) => v.len(),
            ArrayData::Object(v) => v.len(),
            ArrayData::Deferred { .. } => 0,
        }
    }

    /// True when no element is held.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Element `i` as f64 (numeric and bool data; `None` for objects, deferred data or `i` out
    /// of range). Integers beyond 2^53 round.
    pub fn get_f64(&self, i: usize) -> Option<f64> {
        Some(match self {
            ArrayData::Bool(v) => f64::from(u8::from(*v.get(i)?)),
            ArrayData::I8(v) => f64::from(*v.get(i)?),
            ArrayData::I16(v) => f64::from(*v.get(i)?),
            ArrayData::I32(v) => f64::from(*v.get(i)?),
            ArrayData::I64(v) => *v.get(i)? as f64,
            ArrayData::U8(v) => f64::from(*v.get(i)?),
            ArrayData::U16(v) => f64::from(*v.get(i)?),
            ArrayData::U32(v) => f64::from(*v.get(i)?),
            ArrayData::U64(v) => *v.get(i)? as f64,
            ArrayData::F32(v) => f64::from(*v.get(i)?),
            ArrayData::F64(v) => *v.get(i)?,
            ArrayData::Object(_) | ArrayData::Deferred { .. } => return None,
        })
    }

    /// Element `i` as i64 (integer and bool data only; `None` for u64 values above `i64::MAX`).
    pub fn get_i64(&self, i: usize) -> Option<i64> {
        Some(match self {
            ArrayData::Bool(v) => i64::from(*v.get(i)?),
            ArrayData::I8(v) => i64::from(*v.get(i)?),
            ArrayData::I16(v) => i64::from(*v.get(i)?),
            ArrayData::I32(v) => i64::from(*v.get(i)?),
            ArrayData::I64(v) => *v.get(i)?,
            ArrayData::U8(v) => i64::from(*v.get(i)?),
            ArrayData::U16(v) => i64::from(*v.get(i)?),
            ArrayData::U32(v) => i64::from(*v.get(i)?),
            ArrayData::U64(v) => i64::try_from(*v.get(i)?).ok()?,
            _ => return None,
        })
    }
}

impl NdArray {
    /// Number of elements (product of the shape; 1 for a scalar).
    pub fn element_count(&self) -> usize {
        self.shape.iter().product()
    }

    /// All elements as f64 in C order (numeric and bool arrays; `None` for object or deferred
    /// data).
    pub fn to_f64_vec(&self) -> Option<Vec<f64>> {
        if matches!(self.data, ArrayData::Object(_) | ArrayData::Deferred { .. }) {
            return None;
        }
        (0..self.data.len()).map(|i| self.data.get_f64(i)).collect()
    }
}

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// A pickle could not be read: where (file, byte offset, opcode) and why.
#[derive(Debug)]
pub struct PickleError {
    /// The file, when the pickle was read through [`from_path`].
    pub path: Option<PathBuf>,
    /// Byte offset of the opcode being executed (or of the end of input).
    pub offset: u64,
    /// The opcode byte being executed, if any.
    pub opcode: Option<u8>,
    /// Best-effort path of the element being built, e.g. `["samples"][7]["instances"][1]`.
    pub location: Option<String>,
    pub kind: ErrorKind,
}

/// What went wrong in a [`PickleError`].
#[derive(Debug, thiserror::Error)]
pub enum ErrorKind {
    /// A global outside the allow-list (the pickle would have imported and called it).
    #[error("refusing to load global {module}.{name}")]
    ForbiddenGlobal { module: String, name: String },
    /// The input ended early.
    #[error("truncated pickle: {0}")]
    Truncated(String),
    /// The bytes do not form a valid pickle (or one this reader can rebuild).
    #[error("{0}")]
    Invalid(String),
    /// A valid pickle feature this reader does not implement.
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// Nesting deeper than [`MAX_DEPTH`].
    #[error("containers nested deeper than {MAX_DEPTH} levels")]
    TooDeep,
    /// The result would be far larger than the input (shared references multiply).
    #[error("the pickle expands to more than {0} values through shared references")]
    TooLarge(u64),
    /// Reading the input failed.
    #[error("I/O error: {0}")]
    Io(io::Error),
}

impl fmt::Display for PickleError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(path) = &self.path {
            write!(f, "{}: ", path.display())?;
        }
        write!(f, "byte {}", self.offset)?;
        if let Some(op) = self.opcode {
            write!(f, " (opcode {})", opcode_name(op))?;
        }
        if let Some(loc) = &self.location {
            write!(f, " in {loc}")?;
        }
        write!(f, ": {}", self.kind)
    }
}

impl std::error::Error for PickleError {}

impl PickleError {
    /// True when the pickle was refused because it names a global outside the allow-list.
    pub fn is_forbidden_global(&self) -> bool {
        matches!(self.kind, ErrorKind::ForbiddenGlobal { .. })
    }
}

/// Name of an opcode byte as in Python's `pickletools`, or `0xNN` for unknown bytes.
pub fn opcode_name(op: u8) -> Cow<'static, str> {
    let name = match op {
        b'(' => "MARK",
        b'.' => "STOP",
        b'0' => "POP",
        b'1' => "POP_MARK",
        b'2' => "DUP",
        b'F' => "FLOAT",
        b'I' => "INT",
        b'J' => "BININT",
        b'K' => "BININT1",
        b'L' => "LONG",
        b'M' => "BININT2",
        b'N' => "NONE",
        b'P' => "PERSID",
        b'Q' => "BINPERSID",
        b'R' => "REDUCE",
        b'S' => "STRING",
        b'T' => "BINSTRING",
        b'U' => "SHORT_BINSTRING",
        b'V' => "UNICODE",
        b'X' => "BINUNICODE",
        b'a' => "APPEND",
        b'b' => "BUILD",
        b'c' => "GLOBAL",
        b'd' => "DICT",
        b'}' => "EMPTY_DICT",
        b'e' => "APPENDS",
        b'g' => "GET",
        b'h' => "BINGET",
        b'i' => "INST",
        b'j' => "LONG_BINGET",
        b'l' => "LIST",
        b']' => "EMPTY_LIST",
        b'o' => "OBJ",
        b'p' => "PUT",
        b'q' => "BINPUT",
        b'r' => "LONG_BINPUT",
        b's' => "SETITEM",
        b't' => "TUPLE",
        b')' => "EMPTY_TUPLE",
        b'u' => "SETITEMS",
        b'G' => "BINFLOAT",
        0x80 => "PROTO",
        0x81 => "NEWOBJ",
        0x82 => "EXT1",
        0x83 => "EXT2",
        0x84 => "EXT4",
        0x85 => "TUPLE1",
        0x86 => "TUPLE2",
        0x87 => "TUPLE3",
        0x88 => "NEWTRUE",
        0x89 => "NEWFALSE",
        0x8a => "LONG1",
        0x8b => "LONG4",
        b'B' => "BINBYTES",
        b'C' => "SHORT_BINBYTES",
        0x8c => "SHORT_BINUNICODE",
        0x8d => "BINUNICODE8",
        0x8e => "BINBYTES8",
        0x8f => "EMPTY_SET",
        0x90 => "ADDITEMS",
        0x91 => "FROZENSET",
        0x92 => "NEWOBJ_EX",
        0x93 => "STACK_GLOBAL",
        0x94 => "MEMOIZE",
        0x95 => "FRAME",
        0x96 => "BYTEARRAY8",
        0x97 => "NEXT_BUFFER",
        0x98 => "READONLY_BUFFER",
        other => return Cow::Owned(format!("0x{other:02x}")),
    };
    Cow::Borrowed(name)
}

// ---------------------------------------------------------------------------------------------
// Entry points
// ---------------------------------------------------------------------------------------------

/// Options for [`from_reader_with`].
#[derive(Debug, Clone, Default)]
pub struct LoadOptions {
    /// Leave byte strings (`BINSTRING`, `BINBYTES`, `BINBYTES8`) longer than this in the input
    /// and return their [`ByteSpan`] instead of their content. `None` reads everything.
    pub defer_bytes_over: Option<u64>,
}
