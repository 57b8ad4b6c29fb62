//! Safe Python-pickle reader (protocols 0-4) that never executes code.
//!
//! Python's `pickle` format is a small stack machine whose `GLOBAL`/`REDUCE` opcodes can call
//! any importable function. This reader runs the same machine but resolves only an allow-list
//! of globals, each replaced by a Rust re-implementation that builds plain data:
//!
//! | global | what it builds |
//! |---|---|
//! | `numpy.core.multiarray._reconstruct` (also `numpy._core...`) + `numpy.ndarray` | an empty array, filled by `BUILD` |
//! | `numpy.dtype` | a dtype (`f4 f8 i1..i8 u1..u8 b1 O`), byte order from `BUILD` |
//! | `numpy.core.multiarray.scalar` (also `numpy._core...`) | a numpy scalar |
//! | `__builtin__.set` / `builtins.set`, `frozenset` | sets |
//! | `_codecs.encode(str, "latin1")`, `__builtin__.bytes()` | bytes written by Python 3 at protocols 0-2 |
//!
//! Every other global is refused with an error naming it, e.g.
//! `refusing to load global os.system`; persistent ids, extension codes and `NEWOBJ` are refused too.
//!
//! # Conventions
//! - Python-2 `str` (`STRING`, `BINSTRING`, `SHORT_BINSTRING`) decodes as latin-1, exactly like
//!   `pickle.load(f, encoding="latin1")`, so numpy's raw array bytes re-encode to the original
//!   bytes exactly.
//! - numpy arrays are always returned in C (row-major) order with native-endian values; the
//!   file's byte order and layout are decoded away. Object arrays (`dtype('O')`) hold [`Value`]s.
//! - Dicts keep insertion order; a repeated key keeps its first position and its last value, as
//!   in Python. Sets keep the order in which the pickle lists their elements.
//! - Integers outside `i64` are kept as little-endian two's-complement bytes ([`Value::BigInt`]).
//!
//! # Robustness
//! Hostile or truncated input gives a [`PickleError`] with the byte offset and the opcode, never a
//! panic: allocations grow only with bytes actually read, the machine itself does not recurse,
//! nesting is capped at [`MAX_DEPTH`], self-referencing structures are refused, and the total
//! size of the result (shared references are copied) is capped relative to the input length.
//!
//! # Large files
//! [`LoadOptions::defer_bytes_over`] leaves large byte strings in the file and returns their
//! [`ByteSpan`] instead ([`Value::Deferred`], [`ArrayData::Deferred`]), so that e.g. a multi-GB
//! JPEG atlas can be indexed in one streaming pass with bounded memory.
//!
//! # Access
//! [`Value`] has `Option`-returning accessors (`get`, `at`, `as_f64`, ...); [`Value::view`] gives a
//! [`View`] whose accessors return errors that name the path, e.g.
//! `gt.view().get("distanceMeasurement")?.at(3)?.get("p1")?.as_array_f64()?`.

use std::borrow::Cow;
use std::collections::HashMap;
use std::fmt;
use std::hash::{Hash, Hasher};
use std::io::{self, BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

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

/// Rebuild the value pickled in `bytes`.
///
/// # Errors
/// [`PickleError`] for malformed, truncated or refused input.
pub fn from_slice(bytes: &[u8]) -> Result<Value, PickleError> {
    Machine::new(bytes, LoadOptions::default(), Some(bytes.len() as u64)).run()
}

/// Rebuild the value pickled in a stream (buffered internally).
///
/// # Errors
/// [`PickleError`] for malformed, truncated or refused input, or I/O errors.
pub fn from_reader<R: Read>(reader: R) -> Result<Value, PickleError> {
    from_reader_with(reader, &LoadOptions::default())
}

/// Rebuild the value pickled in a stream, with options.
///
/// # Errors
/// [`PickleError`] for malformed, truncated or refused input, or I/O errors.
pub fn from_reader_with<R: Read>(reader: R, options: &LoadOptions) -> Result<Value, PickleError> {
    Machine::new(
        BufReader::with_capacity(1 << 16, reader),
        options.clone(),
        None,
    )
    .run()
}

/// Rebuild the value pickled in the file at `path`; errors name the file.
///
/// # Errors
/// [`PickleError`] (with `path` set) for unreadable, malformed, truncated or refused files.
pub fn from_path(path: &Path, options: &LoadOptions) -> Result<Value, PickleError> {
    let with_path = |mut e: PickleError| {
        e.path = Some(path.to_path_buf());
        e
    };
    let file = std::fs::File::open(path).map_err(|e| {
        with_path(PickleError {
            path: None,
            offset: 0,
            opcode: None,
            location: None,
            kind: ErrorKind::Io(e),
        })
    })?;
    from_reader_with(file, options).map_err(with_path)
}

// ---------------------------------------------------------------------------------------------
// The machine
// ---------------------------------------------------------------------------------------------

type Id = usize;

const ID_NONE: Id = 0;
const ID_FALSE: Id = 1;
const ID_TRUE: Id = 2;

/// Allowed callables, re-implemented.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Callable {
    Reconstruct,
    NdarrayType,
    Dtype,
    Scalar,
    Set,
    FrozenSet,
    CodecsEncode,
    Bytes,
}

fn resolve_global(module: &str, name: &str) -> Option<Callable> {
    let numpy_multiarray = matches!(module, "numpy.core.multiarray" | "numpy._core.multiarray");
    let builtins = matches!(module, "__builtin__" | "builtins");
    match name {
        "_reconstruct" if numpy_multiarray => Some(Callable::Reconstruct),
        "scalar" if numpy_multiarray => Some(Callable::Scalar),
        "ndarray" if module == "numpy" => Some(Callable::NdarrayType),
        "dtype" if module == "numpy" => Some(Callable::Dtype),
        "set" if builtins => Some(Callable::Set),
        "frozenset" if builtins => Some(Callable::FrozenSet),
        "bytes" if builtins => Some(Callable::Bytes),
        "encode" if module == "_codecs" => Some(Callable::CodecsEncode),
        _ => None,
    }
}

#[derive(Debug)]
struct GlobalRef {
    callable: Callable,
    module: String,
    name: String,
}

/// Array data as held by the machine: objects are still node ids.
#[derive(Debug)]
enum Body {
    Typed(ArrayData),
    Objects(Vec<Id>),
}

#[derive(Debug)]
struct ArrayNode {
    /// `None` until `BUILD` gives the state.
    built: Option<(Vec<usize>, Dtype, Body)>,
}

#[derive(Debug)]
enum Node {
    None,
    Bool(bool),
    Int(i64),
    BigInt(Vec<u8>),
    Float(f64),
    Str(String),
    Bytes(Vec<u8>),
    Deferred(ByteSpan),
    List(Vec<Id>),
    Tuple(Vec<Id>),
    Dict(Vec<(Id, Id)>),
    Set(Vec<Id>),
    FrozenSet(Vec<Id>),
    Global(Box<GlobalRef>),
    Dtype(Dtype),
    Array(Box<ArrayNode>),
    Scalar(Box<NdArray>),
    /// Moved into the result.
    Taken,
}

impl Node {
    fn type_name(&self) -> &'static str {
        match self {
            Node::None => "None",
            Node::Bool(_) => "bool",
            Node::Int(_) | Node::BigInt(_) => "int",
            Node::Float(_) => "float",
            Node::Str(_) => "str",
            Node::Bytes(_) | Node::Deferred(_) => "bytes",
            Node::List(_) => "list",
            Node::Tuple(_) => "tuple",
            Node::Dict(_) => "dict",
            Node::Set(_) => "set",
            Node::FrozenSet(_) => "frozenset",
            Node::Global(_) => "global",
            Node::Dtype(_) => "numpy.dtype",
            Node::Array(_) => "numpy.ndarray",
            Node::Scalar(_) => "numpy scalar",
            Node::Taken => "(moved)",
        }
    }
}

/// Reader with a byte position; allocations grow only with bytes actually read.
struct Input<R: BufRead> {
    r: R,
    pos: u64,
}

impl<R: BufRead> Input<R> {
    fn io_err(&self, e: io::Error) -> (u64, ErrorKind) {
        (self.pos, ErrorKind::Io(e))
    }

    fn next_byte(&mut self) -> Result<Option<u8>, (u64, ErrorKind)> {
        loop {
            let buf = match self.r.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(self.io_err(e)),
            };
            let Some(&b) = buf.first() else {
                return Ok(None);
            };
            self.r.consume(1);
            self.pos += 1;
            return Ok(Some(b));
        }
    }

    fn read_vec(&mut self, n: u64, what: &str) -> Result<Vec<u8>, (u64, ErrorKind)> {
        let mut out = Vec::new();
        let got = (&mut self.r)
            .take(n)
            .read_to_end(&mut out)
            .map_err(|e| self.io_err(e))?;
        self.pos += got as u64;
        if (got as u64) < n {
            return Err((
                self.pos,
                ErrorKind::Truncated(format!("{what} needs {n} bytes, only {got} left")),
            ));
        }
        Ok(out)
    }

    fn read_array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], (u64, ErrorKind)> {
        let v = self.read_vec(N as u64, what)?;
        let mut out = [0u8; N];
        out.copy_from_slice(&v);
        Ok(out)
    }

    fn skip(&mut self, n: u64, what: &str) -> Result<(), (u64, ErrorKind)> {
        let got =
            io::copy(&mut (&mut self.r).take(n), &mut io::sink()).map_err(|e| self.io_err(e))?;
        self.pos += got;
        if got < n {
            return Err((
                self.pos,
                ErrorKind::Truncated(format!("{what} needs {n} bytes, only {got} left")),
            ));
        }
        Ok(())
    }

    /// A text argument up to and excluding `\n`.
    fn read_line(&mut self, what: &str) -> Result<Vec<u8>, (u64, ErrorKind)> {
        let mut out = Vec::new();
        let got = self
            .r
            .read_until(b'\n', &mut out)
            .map_err(|e| self.io_err(e))?;
        self.pos += got as u64;
        if out.pop() != Some(b'\n') {
            return Err((
                self.pos,
                ErrorKind::Truncated(format!("{what} is not terminated by a newline")),
            ));
        }
        Ok(out)
    }
}

struct Machine<R: BufRead> {
    input: Input<R>,
    options: LoadOptions,
    /// Total input length when known (for the size budget); otherwise bytes read so far.
    known_len: Option<u64>,
    nodes: Vec<Node>,
    stack: Vec<Id>,
    marks: Vec<usize>,
    memo: Memo,
}

/// The memo: dense for the small, sequential keys picklers write; sparse beyond.
#[derive(Debug, Default)]
struct Memo {
    /// `dense[key]` = node id + 1 (0: empty).
    dense: Vec<u32>,
    sparse: HashMap<u64, Id>,
    /// Distinct keys stored (what `MEMOIZE` uses as the next key).
    count: u64,
}

impl Memo {
    /// Store `id` under `key`; keys below `dense_limit` use the dense table (its memory is then
    /// bounded by the caller's limit).
    fn put(&mut self, key: u64, id: Id, dense_limit: u64) {
        let slot = u32::try_from(id).ok().and_then(|i| i.checked_add(1));
        match (usize::try_from(key), slot) {
            (Ok(k), Some(slot)) if key < dense_limit => {
                if k >= self.dense.len() {
                    self.dense.resize(k + 1, 0);
                }
                if !self.sparse.is_empty() && self.sparse.remove(&key).is_some() {
                    self.count -= 1;
                }
                if self.dense[k] == 0 {
                    self.count += 1;
                }
                self.dense[k] = slot;
            }
            _ => {
                if self.sparse.insert(key, id).is_none() {
                    self.count += 1;
                }
            }
        }
    }

    fn get(&self, key: u64) -> Option<Id> {
        let dense = usize::try_from(key)
            .ok()
            .and_then(|k| self.dense.get(k))
            .filter(|&&slot| slot != 0)
            .map(|&slot| slot as usize - 1);
        dense.or_else(|| self.sparse.get(&key).copied())
    }
}

type StepResult<T> = Result<T, ErrorKind>;

fn invalid<T>(msg: impl Into<String>) -> StepResult<T> {
    Err(ErrorKind::Invalid(msg.into()))
}

impl<R: BufRead> Machine<R> {
    fn new(r: R, options: LoadOptions, known_len: Option<u64>) -> Self {
        Machine {
            input: Input { r, pos: 0 },
            options,
            known_len,
            nodes: vec![Node::None, Node::Bool(false), Node::Bool(true)],
            stack: Vec::new(),
            marks: Vec::new(),
            memo: Memo::default(),
        }
    }

    fn run(mut self) -> Result<Value, PickleError> {
        loop {
            let start = self.input.pos;
            let (op, result) = match self.input.next_byte() {
                Ok(Some(op)) => (Some(op), self.step(op)),
                Ok(None) => (
                    None,
                    Err(ErrorKind::Truncated(
                        "input ended before the STOP opcode".into(),
                    )),
                ),
                Err((_, kind)) => (None, Err(kind)),
            };
            let result = match result {
                Ok(false) => continue,
                Ok(true) => match self.pop() {
                    Ok(root) => {
                        return self.finish(root).map_err(|kind| PickleError {
                            path: None,
                            offset: start,
                            opcode: op,
                            location: None,
                            kind,
                        })
                    }
                    Err(kind) => Err(kind),
                },
                Err(kind) => Err(kind),
            };
            return result.map_err(|kind| PickleError {
                path: None,
                offset: start,
                opcode: op,
                location: self.location(),
                kind,
            });
        }
    }

    /// Best-effort path of the element being built when an error struck, e.g.
    /// `["samples"][7]["instances"][1]`: read from the containers on the stack that are being
    /// filled between MARKs. Exact for the batched APPENDS/SETITEMS that Python's pickler
    /// writes; a container filled by a single APPEND/SETITEM (no MARK) may be missed.
    fn location(&self) -> Option<String> {
        let is_piece = |id: Id| {
            matches!(self.nodes.get(id), Some(Node::Global(_) | Node::Dtype(_)))
                || matches!(self.nodes.get(id), Some(Node::Array(a)) if a.built.is_none())
        };
        let is_container = |id: Id| {
            matches!(
                self.nodes.get(id),
                Some(Node::List(_) | Node::Dict(_) | Node::Set(_))
            )
        };
        let mut path = String::new();
        for (k, &p) in self.marks.iter().enumerate() {
            if p == 0 || p > self.stack.len() {
                break;
            }
            let container = self.stack[p - 1];
            let deeper = k + 1 < self.marks.len();
            let end = self
                .marks
                .get(k + 1)
                .copied()
                .unwrap_or(self.stack.len())
                .clamp(p, self.stack.len());
            let pending = &self.stack[p..end];
            // The element in progress starts at the first piece of an unfinished object, or at
            // a container directly followed by such a piece, or (when a deeper MARK exists) at
            // the container that MARK fills.
            let mut done = pending.len();
            for (i, &id) in pending.iter().enumerate() {
                let next_is_piece = pending.get(i + 1).is_some_and(|&n| is_piece(n));
                if is_piece(id) || (is_container(id) && next_is_piece) {
                    done = i;
                    break;
                }
            }
            if deeper && done == pending.len() {
                done = pending.len().saturating_sub(1);
            }
            // An empty list on top of the innermost segment is most likely about to receive its
            // first element (a vehicle whose first crop is being read).
            let empty_list_on_top = !deeper
                && done == pending.len()
                && pending.last().is_some_and(
                    |&id| matches!(self.nodes.get(id), Some(Node::List(v)) if v.is_empty()),
                );
            if empty_list_on_top {
                done = pending.len() - 1;
            }
            match self.nodes.get(container) {
                Some(Node::List(items)) => path.push_str(&format!("[{}]", items.len() + done)),
                Some(Node::Dict(_)) if done % 2 == 1 => match self.nodes.get(pending[done - 1]) {
                    Some(Node::Str(key)) => path.push_str(&format!("[{key:?}]")),
                    Some(Node::Int(key)) => path.push_str(&format!("[{key}]")),
                    _ => path.push_str("[?]"),
                },
                _ => break,
            }
            if deeper && p + done + 1 == end {
                continue;
            }
            // The element in progress is a list filled without a MARK (a single APPEND): its
            // own element in progress is the next one.
            if let Some(Node::List(items)) = pending.get(done).and_then(|&id| self.nodes.get(id)) {
                path.push_str(&format!("[{}]", items.len()));
            }
            break;
        }
        (!path.is_empty()).then_some(path)
    }

    // --- stack helpers --------------------------------------------------------------------

    fn floor(&self) -> usize {
        self.marks.last().copied().unwrap_or(0)
    }

    fn push_node(&mut self, node: Node) -> Id {
        self.nodes.push(node);
        let id = self.nodes.len() - 1;
        self.stack.push(id);
        id
    }

    fn pop(&mut self) -> StepResult<Id> {
        if self.stack.len() <= self.floor() {
            return invalid("stack underflow");
        }
        match self.stack.pop() {
            Some(id) => Ok(id),
            None => invalid("stack underflow"),
        }
    }

    fn top(&self) -> StepResult<Id> {
        if self.stack.len() <= self.floor() {
            return invalid("stack underflow");
        }
        match self.stack.last() {
            Some(&id) => Ok(id),
            None => invalid("stack underflow"),
        }
    }

    fn pop_mark(&mut self) -> StepResult<Vec<Id>> {
        let Some(mark) = self.marks.pop() else {
            return invalid("no MARK on the stack");
        };
        if mark > self.stack.len() {
            return invalid("corrupt MARK");
        }
        Ok(self.stack.split_off(mark))
    }

    fn node(&self, id: Id) -> StepResult<&Node> {
        match self.nodes.get(id) {
            Some(n) => Ok(n),
            None => invalid("internal: dangling node id"),
        }
    }

    fn node_mut(&mut self, id: Id) -> StepResult<&mut Node> {
        match self.nodes.get_mut(id) {
            Some(n) => Ok(n),
            None => invalid("internal: dangling node id"),
        }
    }

    fn io<T>(&mut self, r: Result<T, (u64, ErrorKind)>) -> StepResult<T> {
        r.map_err(|(_, kind)| kind)
    }

    fn read_line(&mut self, what: &str) -> StepResult<Vec<u8>> {
        let r = self.input.read_line(what);
        self.io(r)
    }

    fn read_vec(&mut self, n: u64, what: &str) -> StepResult<Vec<u8>> {
        let r = self.input.read_vec(n, what);
        self.io(r)
    }

    fn read_u8(&mut self, what: &str) -> StepResult<u8> {
        let r = self.input.read_array::<1>(what);
        Ok(self.io(r)?[0])
    }

    fn read_u16(&mut self, what: &str) -> StepResult<u16> {
        let r = self.input.read_array::<2>(what);
        Ok(u16::from_le_bytes(self.io(r)?))
    }

    fn read_u32(&mut self, what: &str) -> StepResult<u32> {
        let r = self.input.read_array::<4>(what);
        Ok(u32::from_le_bytes(self.io(r)?))
    }

    fn read_i32(&mut self, what: &str) -> StepResult<i32> {
        let r = self.input.read_array::<4>(what);
        Ok(i32::from_le_bytes(self.io(r)?))
    }

    fn read_u64(&mut self, what: &str) -> StepResult<u64> {
        let r = self.input.read_array::<8>(what);
        Ok(u64::from_le_bytes(self.io(r)?))
    }

    /// A byte-string payload of `n` bytes that may be deferred.
    fn byte_payload(&mut self, n: u64, what: &str) -> StepResult<Result<Vec<u8>, ByteSpan>> {
        if let Some(limit) = self.options.defer_bytes_over {
            if n > limit {
                let span = ByteSpan {
                    offset: self.input.pos,
                    len: n,
                };
                let r = self.input.skip(n, what);
                self.io(r)?;
                return Ok(Err(span));
            }
        }
        Ok(Ok(self.read_vec(n, what)?))
    }

    fn len_to_u64(n: i64, what: &str) -> StepResult<u64> {
        u64::try_from(n).or_else(|_| invalid(format!("{what} has negative length {n}")))
    }

    // --- one opcode -----------------------------------------------------------------------

    /// Execute one opcode; `Ok(true)` at STOP.
    fn step(&mut self, op: u8) -> StepResult<bool> {
        match op {
            0x80 => {
                let proto = self.read_u8("protocol number")?;
                if proto > MAX_PROTOCOL {
                    return Err(ErrorKind::Unsupported(format!(
                        "pickle protocol {proto} (this reader handles 0-{MAX_PROTOCOL})"
                    )));
                }
            }
            0x95 => {
                // FRAME: framing only groups opcodes for I/O; the length is not needed.
                self.read_u64("frame length")?;
            }
            b'.' => return Ok(true),
            b'(' => self.marks.push(self.stack.len()),
            b'0' => {
                if self.stack.len() > self.floor() {
                    self.pop()?;
                } else {
                    self.pop_mark()?;
                }
            }
            b'1' => {
                self.pop_mark()?;
            }
            b'2' => {
                let id = self.top()?;
                self.stack.push(id);
            }
            // --- atoms ---
            b'N' => self.stack.push(ID_NONE),
            0x88 => self.stack.push(ID_TRUE),
            0x89 => self.stack.push(ID_FALSE),
            b'I' => {
                let line = self.read_line("INT argument")?;
                match line.as_slice() {
                    b"01" => self.stack.push(ID_TRUE),
                    b"00" => self.stack.push(ID_FALSE),
                    _ => {
                        let node = parse_decimal_int(&line)?;
                        self.push_node(node);
                    }
                }
            }
            b'L' => {
                let mut line = self.read_line("LONG argument")?;
                if line.last() == Some(&b'L') {
                    line.pop();
                }
                let node = parse_decimal_int(&line)?;
                self.push_node(node);
            }
            b'J' => {
                let v = self.read_i32("BININT argument")?;
                self.push_node(Node::Int(i64::from(v)));
            }
            b'K' => {
                let v = self.read_u8("BININT1 argument")?;
                self.push_node(Node::Int(i64::from(v)));
            }
            b'M' => {
                let v = self.read_u16("BININT2 argument")?;
                self.push_node(Node::Int(i64::from(v)));
            }
            0x8a => {
                let n = self.read_u8("LONG1 length")?;
                let bytes = self.read_vec(u64::from(n), "LONG1 payload")?;
                self.push_node(int_from_le(bytes));
            }
            0x8b => {
                let n = self.read_i32("LONG4 length")?;
                let n = Self::len_to_u64(i64::from(n), "LONG4")?;
                let bytes = self.read_vec(n, "LONG4 payload")?;
                self.push_node(int_from_le(bytes));
            }
            b'F' => {
                let line = self.read_line("FLOAT argument")?;
                let text = std::str::from_utf8(&line).unwrap_or("");
                match text.trim().parse::<f64>() {
                    Ok(v) => {
                        self.push_node(Node::Float(v));
                    }
                    Err(_) => {
                        return invalid(format!(
                            "FLOAT argument {:?} is not a number",
                            String::from_utf8_lossy(&line)
                        ))
                    }
                }
            }
            b'G' => {
                let r = self.input.read_array::<8>("BINFLOAT argument");
                let bytes = self.io(r)?;
                self.push_node(Node::Float(f64::from_be_bytes(bytes)));
            }
            // --- strings ---
            b'S' => {
                let line = self.read_line("STRING argument")?;
                let bytes = unquote_string(&line)?;
                self.push_node(Node::Str(latin1(&bytes)));
            }
            b'T' => {
                let n = self.read_i32("BINSTRING length")?;
                let n = Self::len_to_u64(i64::from(n), "BINSTRING")?;
                let node = match self.byte_payload(n, "BINSTRING payload")? {
                    Ok(bytes) => Node::Str(latin1(&bytes)),
                    Err(span) => Node::Deferred(span),
                };
                self.push_node(node);
            }
            b'U' => {
                let n = self.read_u8("SHORT_BINSTRING length")?;
                let bytes = self.read_vec(u64::from(n), "SHORT_BINSTRING payload")?;
                self.push_node(Node::Str(latin1(&bytes)));
            }
            b'V' => {
                let line = self.read_line("UNICODE argument")?;
                let s = raw_unicode_escape_decode(&line)?;
                self.push_node(Node::Str(s));
            }
            b'X' => {
                let n = self.read_u32("BINUNICODE length")?;
                self.push_utf8(u64::from(n), "BINUNICODE payload")?;
            }
            0x8c => {
                let n = self.read_u8("SHORT_BINUNICODE length")?;
                self.push_utf8(u64::from(n), "SHORT_BINUNICODE payload")?;
            }
            0x8d => {
                let n = self.read_u64("BINUNICODE8 length")?;
                self.push_utf8(n, "BINUNICODE8 payload")?;
            }
            b'B' => {
                let n = self.read_u32("BINBYTES length")?;
                self.push_bytes(u64::from(n), "BINBYTES payload")?;
            }
            b'C' => {
                let n = self.read_u8("SHORT_BINBYTES length")?;
                let bytes = self.read_vec(u64::from(n), "SHORT_BINBYTES payload")?;
                self.push_node(Node::Bytes(bytes));
            }
            0x8e => {
                let n = self.read_u64("BINBYTES8 length")?;
                self.push_bytes(n, "BINBYTES8 payload")?;
            }
            // --- containers ---
            b']' => {
                self.push_node(Node::List(Vec::new()));
            }
            b'}' => {
                self.push_node(Node::Dict(Vec::new()));
            }
            b')' => {
                self.push_node(Node::Tuple(Vec::new()));
            }
            0x8f => {
                self.push_node(Node::Set(Vec::new()));
            }
            b'l' => {
                let items = self.pop_mark()?;
                self.push_node(Node::List(items));
            }
            b't' => {
                let items = self.pop_mark()?;
                self.push_node(Node::Tuple(items));
            }
            0x91 => {
                let items = self.pop_mark()?;
                self.push_node(Node::FrozenSet(items));
            }
            0x85..=0x87 => {
                let n = usize::from(op - 0x84);
                if self.stack.len() < self.floor() + n {
                    return invalid("stack underflow");
                }
                let items = self.stack.split_off(self.stack.len() - n);
                self.push_node(Node::Tuple(items));
            }
            b'd' => {
                let items = self.pop_mark()?;
                let pairs = pairs_of(items)?;
                self.push_node(Node::Dict(pairs));
            }
            b'a' => {
                let v = self.pop()?;
                let target = self.top()?;
                match self.node_mut(target)? {
                    Node::List(items) => items.push(v),
                    other => return invalid(format!("APPEND to a {}", other.type_name())),
                }
            }
            b'e' => {
                let items = self.pop_mark()?;
                let target = self.top()?;
                match self.node_mut(target)? {
                    Node::List(list) => list.extend(items),
                    other => return invalid(format!("APPENDS to a {}", other.type_name())),
                }
            }
            b's' => {
                let v = self.pop()?;
                let k = self.pop()?;
                let target = self.top()?;
                match self.node_mut(target)? {
                    Node::Dict(items) => items.push((k, v)),
                    other => return invalid(format!("SETITEM on a {}", other.type_name())),
                }
            }
            b'u' => {
                let items = self.pop_mark()?;
                let pairs = pairs_of(items)?;
                let target = self.top()?;
                match self.node_mut(target)? {
                    Node::Dict(items) => items.extend(pairs),
                    other => return invalid(format!("SETITEMS on a {}", other.type_name())),
                }
            }
            0x90 => {
                let items = self.pop_mark()?;
                let target = self.top()?;
                match self.node_mut(target)? {
                    Node::Set(set) => set.extend(items),
                    other => return invalid(format!("ADDITEMS on a {}", other.type_name())),
                }
            }
            // --- memo ---
            b'p' => {
                let line = self.read_line("PUT argument")?;
                let key = parse_memo_key(&line)?;
                let id = self.top()?;
                self.memo.put(key, id, self.dense_memo_limit());
            }
            b'q' => {
                let key = self.read_u8("BINPUT argument")?;
                let id = self.top()?;
                self.memo.put(u64::from(key), id, self.dense_memo_limit());
            }
            b'r' => {
                let key = self.read_u32("LONG_BINPUT argument")?;
                let id = self.top()?;
                self.memo.put(u64::from(key), id, self.dense_memo_limit());
            }
            0x94 => {
                let id = self.top()?;
                let key = self.memo.count;
                self.memo.put(key, id, self.dense_memo_limit());
            }
            b'g' => {
                let line = self.read_line("GET argument")?;
                let key = parse_memo_key(&line)?;
                self.get_memo(key)?;
            }
            b'h' => {
                let key = self.read_u8("BINGET argument")?;
                self.get_memo(u64::from(key))?;
            }
            b'j' => {
                let key = self.read_u32("LONG_BINGET argument")?;
                self.get_memo(u64::from(key))?;
            }
            // --- globals and calls ---
            b'c' => {
                let module = self.read_line("GLOBAL module")?;
                let name = self.read_line("GLOBAL name")?;
                let module = String::from_utf8_lossy(&module).into_owned();
                let name = String::from_utf8_lossy(&name).into_owned();
                self.push_global(module, name)?;
            }
            0x93 => {
                let name = self.pop()?;
                let module = self.pop()?;
                let (Node::Str(module), Node::Str(name)) = (self.node(module)?, self.node(name)?)
                else {
                    return invalid("STACK_GLOBAL requires two str arguments");
                };
                let (module, name) = (module.clone(), name.clone());
                self.push_global(module, name)?;
            }
            b'R' => {
                let args = self.pop()?;
                let func = self.pop()?;
                let args = match self.node(args)? {
                    Node::Tuple(items) => items.clone(),
                    other => {
                        return invalid(format!(
                            "REDUCE arguments must be a tuple, found {}",
                            other.type_name()
                        ))
                    }
                };
                let node = self.call(func, &args)?;
                self.push_node(node);
            }
            b'i' => {
                let module = self.read_line("INST module")?;
                let name = self.read_line("INST name")?;
                let module = String::from_utf8_lossy(&module).into_owned();
                let name = String::from_utf8_lossy(&name).into_owned();
                let args = self.pop_mark()?;
                self.push_global(module, name)?;
                let func = self.pop()?;
                let node = self.call(func, &args)?;
                self.push_node(node);
            }
            b'o' => {
                let mut items = self.pop_mark()?;
                if items.is_empty() {
                    return invalid("OBJ without a class");
                }
                let func = items.remove(0);
                let node = self.call(func, &items)?;
                self.push_node(node);
            }
            0x81 | 0x92 => {
                if op == 0x92 {
                    self.pop()?; // kwargs
                }
                self.pop()?; // args
                let cls = self.pop()?;
                let what = match self.node(cls)? {
                    Node::Global(g) => format!("{}.{}", g.module, g.name),
                    other => other.type_name().to_string(),
                };
                return Err(ErrorKind::Unsupported(format!(
                    "creating {what} through {}",
                    opcode_name(op)
                )));
            }
            b'b' => {
                let state = self.pop()?;
                let target = self.top()?;
                self.build(target, state)?;
            }
            b'P' | b'Q' => {
                return Err(ErrorKind::Unsupported(
                    "persistent ids (they need an application-defined loader)".into(),
                ))
            }
            0x82..=0x84 => {
                return Err(ErrorKind::Unsupported(
                    "extension codes (copyreg registry; they resolve to arbitrary globals)".into(),
                ))
            }
            0x96..=0x98 => {
                return Err(ErrorKind::Unsupported(
                    "protocol 5 out-of-band buffers".into(),
                ))
            }
            other => {
                return invalid(format!("unknown opcode 0x{other:02x}"));
            }
        }
        Ok(false)
    }

    fn push_utf8(&mut self, n: u64, what: &str) -> StepResult<()> {
        let bytes = self.read_vec(n, what)?;
        match String::from_utf8(bytes) {
            Ok(s) => {
                self.push_node(Node::Str(s));
                Ok(())
            }
            Err(e) => invalid(format!("{what} is not valid UTF-8: {}", e.utf8_error())),
        }
    }

    fn push_bytes(&mut self, n: u64, what: &str) -> StepResult<()> {
        let node = match self.byte_payload(n, what)? {
            Ok(bytes) => Node::Bytes(bytes),
            Err(span) => Node::Deferred(span),
        };
        self.push_node(node);
        Ok(())
    }

    /// Memo keys below this go to the dense table: picklers number memoized objects
    /// sequentially, so real keys stay below the number of objects built.
    fn dense_memo_limit(&self) -> u64 {
        self.nodes.len() as u64 + 1024
    }

    fn get_memo(&mut self, key: u64) -> StepResult<()> {
        match self.memo.get(key) {
            Some(id) => {
                self.stack.push(id);
                Ok(())
            }
            None => invalid(format!("memo key {key} was never stored")),
        }
    }

    fn push_global(&mut self, module: String, name: String) -> StepResult<()> {
        match resolve_global(&module, &name) {
            Some(callable) => {
                self.push_node(Node::Global(Box::new(GlobalRef {
                    callable,
                    module,
                    name,
                })));
                Ok(())
            }
            None => Err(ErrorKind::ForbiddenGlobal { module, name }),
        }
    }

    // --- allowed callables ----------------------------------------------------------------

    fn call(&mut self, func: Id, args: &[Id]) -> StepResult<Node> {
        let (callable, fname) = match self.node(func)? {
            Node::Global(g) => (g.callable, format!("{}.{}", g.module, g.name)),
            other => return invalid(format!("calling a {}, not a global", other.type_name())),
        };
        match callable {
            Callable::Reconstruct => {
                let Some(&subtype) = args.first() else {
                    return invalid(format!("{fname} without arguments"));
                };
                match self.node(subtype)? {
                    Node::Global(g) if g.callable == Callable::NdarrayType => {}
                    Node::Global(g) => {
                        return Err(ErrorKind::Unsupported(format!(
                            "{fname} of {}.{} (only numpy.ndarray)",
                            g.module, g.name
                        )))
                    }
                    other => {
                        return invalid(format!(
                            "{fname} of a {}, expected numpy.ndarray",
                            other.type_name()
                        ))
                    }
                }
                Ok(Node::Array(Box::new(ArrayNode { built: None })))
            }
            Callable::NdarrayType => Err(ErrorKind::Unsupported(format!(
                "calling {fname} directly (only through _reconstruct)"
            ))),
            Callable::Dtype => {
                let Some(&descr) = args.first() else {
                    return invalid(format!("{fname} without arguments"));
                };
                let descr = match self.node(descr)? {
                    Node::Str(s) => s.clone(),
                    Node::Bytes(b) => latin1(b),
                    other => {
                        return invalid(format!(
                            "{fname} descriptor must be a str, found {}",
                            other.type_name()
                        ))
                    }
                };
                Ok(Node::Dtype(parse_dtype(&descr)?))
            }
            Callable::Scalar => {
                let (Some(&dtype), Some(&data)) = (args.first(), args.get(1)) else {
                    return invalid(format!("{fname} needs (dtype, data)"));
                };
                let dtype = match self.node(dtype)? {
                    Node::Dtype(d) => *d,
                    other => {
                        return invalid(format!(
                            "{fname} dtype argument is a {}",
                            other.type_name()
                        ))
                    }
                };
                if dtype.kind == DtypeKind::Object {
                    return invalid(format!(
                        "{fname} of dtype object (numpy never pickles those)"
                    ));
                }
                let bytes = match self.node(data)? {
                    Node::Str(s) => latin1_bytes(s)?,
                    Node::Bytes(b) => b.clone(),
                    other => {
                        return invalid(format!(
                            "{fname} data must be a byte string, found {}",
                            other.type_name()
                        ))
                    }
                };
                let data = decode_elements(&bytes, dtype, 1)?;
                Ok(Node::Scalar(Box::new(NdArray {
                    shape: Vec::new(),
                    dtype,
                    data,
                })))
            }
            Callable::Set | Callable::FrozenSet => {
                let items = match args {
                    [] => Vec::new(),
                    [it] => match self.node(*it)? {
                        Node::List(v) | Node::Tuple(v) | Node::Set(v) | Node::FrozenSet(v) => {
                            v.clone()
                        }
                        other => {
                            return invalid(format!(
                                "{fname} of a {} (expected a list)",
                                other.type_name()
                            ))
                        }
                    },
                    _ => return invalid(format!("{fname} takes at most one argument")),
                };
                Ok(if callable == Callable::Set {
                    Node::Set(items)
                } else {
                    Node::FrozenSet(items)
                })
            }
            Callable::CodecsEncode => {
                let (Some(&text), Some(&encoding)) = (args.first(), args.get(1)) else {
                    return invalid(format!("{fname} needs (text, encoding)"));
                };
                let encoding = match self.node(encoding)? {
                    Node::Str(e) => e.to_ascii_lowercase(),
                    other => {
                        return invalid(format!(
                            "{fname} encoding must be a str, found {}",
                            other.type_name()
                        ))
                    }
                };
                let Node::Str(text) = self.node(text)? else {
                    return invalid(format!("{fname} text must be a str"));
                };
                match encoding.as_str() {
                    "latin1" | "latin-1" | "iso-8859-1" | "iso8859-1" => {
                        Ok(Node::Bytes(latin1_bytes(text)?))
                    }
                    "utf-8" | "utf8" => Ok(Node::Bytes(text.as_bytes().to_vec())),
                    _ => Err(ErrorKind::Unsupported(format!(
                        "{fname} with encoding {encoding:?}"
                    ))),
                }
            }
            Callable::Bytes => {
                if args.is_empty() {
                    Ok(Node::Bytes(Vec::new()))
                } else {
                    Err(ErrorKind::Unsupported(format!(
                        "{fname} with arguments (only bytes() is pickled by Python)"
                    )))
                }
            }
        }
    }

    fn build(&mut self, target: Id, state: Id) -> StepResult<()> {
        match self.node(target)? {
            Node::Dtype(_) => {
                let dtype = self.dtype_state(target, state)?;
                *self.node_mut(target)? = Node::Dtype(dtype);
                Ok(())
            }
            Node::Array(_) => {
                let built = self.array_state(state)?;
                *self.node_mut(target)? = Node::Array(Box::new(ArrayNode { built: Some(built) }));
                Ok(())
            }
            other => Err(ErrorKind::Unsupported(format!(
                "BUILD (setting state) on a {}",
                other.type_name()
            ))),
        }
    }

    fn tuple_items(&self, id: Id, what: &str) -> StepResult<Vec<Id>> {
        match self.node(id)? {
            Node::Tuple(items) => Ok(items.clone()),
            other => invalid(format!(
                "{what} must be a tuple, found {}",
                other.type_name()
            )),
        }
    }

    /// numpy.dtype.__setstate__: (version, byteorder, subarray, names, fields, elsize,
    /// alignment, flags[, metadata]).
    fn dtype_state(&self, target: Id, state: Id) -> StepResult<Dtype> {
        let Node::Dtype(mut dtype) = *self.node(target)? else {
            return invalid("internal: dtype expected");
        };
        let items = self.tuple_items(state, "numpy.dtype state")?;
        if items.len() < 2 {
            return invalid(format!(
                "numpy.dtype state has {} items, expected at least 2",
                items.len()
            ));
        }
        match self.node(items[1])? {
            Node::Str(order) => match order.as_str() {
                ">" => dtype.big_endian = true,
                "<" | "|" | "=" => dtype.big_endian = false,
                other => return invalid(format!("numpy.dtype byte order {other:?}")),
            },
            other => return invalid(format!("numpy.dtype byte order is a {}", other.type_name())),
        }
        for (i, what) in [(2, "subarray"), (3, "field names"), (4, "fields")] {
            if let Some(&id) = items.get(i) {
                if !matches!(self.node(id)?, Node::None) {
                    return Err(ErrorKind::Unsupported(format!(
                        "structured numpy dtypes (the dtype has {what})"
                    )));
                }
            }
        }
        Ok(dtype)
    }

    /// numpy.ndarray.__setstate__: ([version,] shape, dtype, is_fortran, rawdata).
    fn array_state(&self, state: Id) -> StepResult<(Vec<usize>, Dtype, Body)> {
        let items = self.tuple_items(state, "numpy.ndarray state")?;
        let items = match items.len() {
            5 => &items[1..],
            4 => &items[..],
            n => {
                return invalid(format!(
                    "numpy.ndarray state has {n} items, expected 4 or 5"
                ))
            }
        };
        let shape_items = self.tuple_items(items[0], "numpy.ndarray shape")?;
        let mut shape = Vec::with_capacity(shape_items.len());
        for id in shape_items {
            match self.node(id)? {
                Node::Int(n) if *n >= 0 => shape.push(usize::try_from(*n).unwrap_or(usize::MAX)),
                Node::Int(n) => return invalid(format!("numpy.ndarray shape has negative {n}")),
                other => {
                    return invalid(format!("numpy.ndarray shape holds a {}", other.type_name()))
                }
            }
        }
        let count = shape
            .iter()
            .try_fold(1usize, |acc, &d| acc.checked_mul(d))
            .ok_or_else(|| {
                ErrorKind::Invalid(format!("numpy.ndarray shape {shape:?} overflows"))
            })?;
        let dtype = match self.node(items[1])? {
            Node::Dtype(d) => *d,
            other => return invalid(format!("numpy.ndarray dtype is a {}", other.type_name())),
        };
        let fortran = match self.node(items[2])? {
            Node::Bool(b) => *b,
            Node::Int(i) => *i != 0,
            other => {
                return invalid(format!(
                    "numpy.ndarray is_fortran flag is a {}",
                    other.type_name()
                ))
            }
        };
        if dtype.kind == DtypeKind::Object {
            let Node::List(objs) = self.node(items[3])? else {
                return invalid("numpy object array data must be a list");
            };
            if objs.len() != count {
                return invalid(format!(
                    "numpy object array of shape {shape:?} has {} elements",
                    objs.len()
                ));
            }
            // numpy pickles object arrays element by element in C order, whatever the layout.
            return Ok((shape, dtype, Body::Objects(objs.clone())));
        }
        let nbytes = count.checked_mul(dtype.itemsize).ok_or_else(|| {
            ErrorKind::Invalid(format!("numpy.ndarray shape {shape:?} overflows"))
        })?;
        let data = match self.node(items[3])? {
            Node::Deferred(span) => {
                if span.len != nbytes as u64 {
                    return invalid(format!(
                        "numpy.ndarray {} of shape {shape:?} needs {nbytes} bytes, found {}",
                        dtype.descr(),
                        span.len
                    ));
                }
                let fortran_order = fortran && shape.len() > 1;
                return Ok((
                    shape,
                    dtype,
                    Body::Typed(ArrayData::Deferred {
                        span: *span,
                        fortran_order,
                    }),
                ));
            }
            Node::Str(s) => Cow::Owned(latin1_bytes(s)?),
            Node::Bytes(b) => Cow::Borrowed(b.as_slice()),
            other => return invalid(format!("numpy.ndarray data is a {}", other.type_name())),
        };
        if data.len() != nbytes {
            return invalid(format!(
                "numpy.ndarray {} of shape {shape:?} needs {nbytes} bytes, found {}",
                dtype.descr(),
                data.len()
            ));
        }
        let mut decoded = decode_elements(&data, dtype, count)?;
        if fortran && shape.len() > 1 {
            decoded = fortran_to_c(decoded, &shape);
        }
        Ok((shape, dtype, Body::Typed(decoded)))
    }

    // --- result ---------------------------------------------------------------------------

    fn finish(mut self, root: Id) -> StepResult<Value> {
        let input_len = self.known_len.unwrap_or(self.input.pos);
        let budget = input_len.saturating_mul(16).saturating_add(1 << 20);
        // The memo and the stack are not needed any more.
        self.memo = Memo::default();
        self.stack = Vec::new();
        let mut conv = Converter {
            state: vec![VISIT_NEW; self.nodes.len()],
            refs: vec![0; self.nodes.len()],
            cache: HashMap::new(),
        };
        let cost = conv.analyse(&self.nodes, root, 0)?;
        if cost > budget {
            return Err(ErrorKind::TooLarge(budget));
        }
        conv.state = Vec::new();
        conv.refs[root] = 1;
        conv.build(&mut self.nodes, root)
    }
}

// ---------------------------------------------------------------------------------------------
// From nodes to values
// ---------------------------------------------------------------------------------------------

/// `Converter::state` of a node not visited yet.
const VISIT_NEW: u64 = u64::MAX;
/// `Converter::state` of a node whose children are being visited.
const VISIT_IN_PROGRESS: u64 = u64::MAX - 1;
/// Expanded costs saturate below the two markers.
const MAX_COST: u64 = u64::MAX - 2;

struct Converter {
    /// Per node: [`VISIT_NEW`], [`VISIT_IN_PROGRESS`] or the expanded cost once visited.
    state: Vec<u64>,
    /// Number of references to each node from the reachable graph.
    refs: Vec<u32>,
    /// Converted values of shared nodes, with the number of uses left.
    cache: HashMap<Id, (Value, u32)>,
}

fn children(node: &Node) -> Box<dyn Iterator<Item = Id> + '_> {
    match node {
        Node::List(v) | Node::Tuple(v) | Node::Set(v) | Node::FrozenSet(v) => {
            Box::new(v.iter().copied())
        }
        Node::Dict(pairs) => Box::new(pairs.iter().flat_map(|&(k, v)| [k, v])),
        Node::Array(a) => match &a.built {
            Some((_, _, Body::Objects(ids))) => Box::new(ids.iter().copied()),
            _ => Box::new(std::iter::empty()),
        },
        _ => Box::new(std::iter::empty()),
    }
}

fn own_cost(node: &Node) -> u64 {
    let payload = match node {
        Node::Str(s) => s.len(),
        Node::Bytes(b) | Node::BigInt(b) => b.len(),
        Node::Array(a) => match &a.built {
            Some((_, dtype, Body::Typed(d))) => d.len().saturating_mul(dtype.itemsize),
            _ => 0,
        },
        _ => 0,
    };
    1 + payload as u64 / 8
}

impl Converter {
    /// Count references, detect cycles and depth, and return the expanded cost of `id`.
    fn analyse(&mut self, nodes: &[Node], id: Id, depth: usize) -> StepResult<u64> {
        if depth > MAX_DEPTH {
            return Err(ErrorKind::TooDeep);
        }
        match self.state.get(id) {
            Some(&VISIT_NEW) => {}
            Some(&VISIT_IN_PROGRESS) => {
                return Err(ErrorKind::Unsupported(
                    "self-referencing structures (a container that contains itself)".into(),
                ))
            }
            Some(&cost) => return Ok(cost),
            None => return invalid("internal: dangling node id"),
        }
        self.state[id] = VISIT_IN_PROGRESS;
        let Some(node) = nodes.get(id) else {
            return invalid("internal: dangling node id");
        };
        match node {
            Node::Global(g) => {
                return Err(ErrorKind::Unsupported(format!(
                    "global {}.{} as a value (only calls to it are rebuilt)",
                    g.module, g.name
                )))
            }
            Node::Dtype(d) => {
                return Err(ErrorKind::Unsupported(format!(
                    "numpy.dtype {} as a value",
                    d.descr()
                )))
            }
            Node::Array(a) if a.built.is_none() => {
                return invalid("numpy array whose state was never set (no BUILD)")
            }
            _ => {}
        }
        let mut cost = own_cost(node);
        for child in children(node) {
            if let Some(r) = self.refs.get_mut(child) {
                *r = r.saturating_add(1);
            }
            cost = cost.saturating_add(self.analyse(nodes, child, depth + 1)?);
        }
        self.state[id] = cost.min(MAX_COST);
        Ok(cost)
    }

    fn build(&mut self, nodes: &mut [Node], id: Id) -> StepResult<Value> {
        if let Some((value, uses_left)) = self.cache.get_mut(&id) {
            *uses_left = uses_left.saturating_sub(1);
            if *uses_left > 0 {
                return Ok(value.clone());
            }
            if let Some((value, _)) = self.cache.remove(&id) {
                return Ok(value);
            }
        }
        let Some(slot) = nodes.get_mut(id) else {
            return invalid("internal: dangling node id");
        };
        // Ids 0-2 are the shared None/False/True constants: never move them.
        let node = if id <= ID_TRUE {
            match slot {
                Node::Bool(b) => Node::Bool(*b),
                _ => Node::None,
            }
        } else {
            std::mem::replace(slot, Node::Taken)
        };
        let value = match node {
            Node::None => Value::None,
            Node::Bool(b) => Value::Bool(b),
            Node::Int(i) => Value::Int(i),
            Node::BigInt(b) => Value::BigInt(b),
            Node::Float(f) => Value::Float(f),
            Node::Str(s) => Value::Str(s),
            Node::Bytes(b) => Value::Bytes(b),
            Node::Deferred(span) => Value::Deferred(span),
            Node::List(ids) => Value::List(self.build_all(nodes, &ids)?),
            Node::Tuple(ids) => Value::Tuple(self.build_all(nodes, &ids)?),
            Node::Set(ids) => Value::Set(dedupe_set(self.build_all(nodes, &ids)?)?),
            Node::FrozenSet(ids) => Value::FrozenSet(dedupe_set(self.build_all(nodes, &ids)?)?),
            Node::Dict(pairs) => {
                let mut out = Vec::with_capacity(pairs.len());
                for (k, v) in pairs {
                    let k = self.build(nodes, k)?;
                    let v = self.build(nodes, v)?;
                    out.push((k, v));
                }
                Value::Dict(dedupe_dict(out)?)
            }
            Node::Scalar(a) => Value::Scalar(a),
            Node::Array(a) => match a.built {
                Some((shape, dtype, Body::Typed(data))) => {
                    Value::Array(Box::new(NdArray { shape, dtype, data }))
                }
                Some((shape, dtype, Body::Objects(ids))) => Value::Array(Box::new(NdArray {
                    shape,
                    dtype,
                    data: ArrayData::Object(self.build_all(nodes, &ids)?),
                })),
                None => return invalid("numpy array whose state was never set (no BUILD)"),
            },
            Node::Global(_) | Node::Dtype(_) | Node::Taken => {
                return invalid("internal: node is not a value")
            }
        };
        let refs = self.refs.get(id).copied().unwrap_or(1);
        if refs > 1 {
            self.cache.insert(id, (value.clone(), refs - 1));
        }
        Ok(value)
    }

    fn build_all(&mut self, nodes: &mut [Node], ids: &[Id]) -> StepResult<Vec<Value>> {
        ids.iter().map(|&id| self.build(nodes, id)).collect()
    }
}

/// Hash/equality of values as Python dict keys (1 == 1.0 == True; lists are unhashable).
struct KeyRef<'a>(&'a Value);

/// A number as Python compares them: integral values as integers.
#[derive(PartialEq, Eq, Hash)]
enum NumKey {
    Int(i64),
    Float(u64),
    Big(Vec<u8>),
}

fn num_key(v: &Value) -> Option<NumKey> {
    let from_f64 = |f: f64| {
        if f.fract() == 0.0 && (-9.223_372_036_854_776e18..9.223_372_036_854_776e18).contains(&f) {
            NumKey::Int(f as i64)
        } else {
            NumKey::Float(f.to_bits())
        }
    };
    match v {
        Value::Bool(b) => Some(NumKey::Int(i64::from(*b))),
        Value::Int(i) => Some(NumKey::Int(*i)),
        Value::BigInt(b) => Some(NumKey::Big(b.clone())),
        Value::Float(f) => Some(from_f64(*f)),
        Value::Scalar(a) => match &a.data {
            ArrayData::F32(_) | ArrayData::F64(_) => a.data.get_f64(0).map(from_f64),
            ArrayData::U64(v) => v.first().map(|&u| match i64::try_from(u) {
                Ok(i) => NumKey::Int(i),
                Err(_) => NumKey::Big(u.to_le_bytes().into_iter().chain([0]).collect()),
            }),
            d => d.get_i64(0).map(NumKey::Int),
        },
        _ => None,
    }
}

fn check_hashable(v: &Value) -> StepResult<()> {
    match v {
        Value::List(_) | Value::Dict(_) | Value::Set(_) | Value::Array(_) => invalid(format!(
            "unhashable {} used as a dict key or set element",
            v.type_name()
        )),
        Value::Tuple(items) | Value::FrozenSet(items) => items.iter().try_for_each(check_hashable),
        _ => Ok(()),
    }
}

impl Hash for KeyRef<'_> {
    fn hash<H: Hasher>(&self, state: &mut H) {
        if let Some(n) = num_key(self.0) {
            n.hash(state);
            return;
        }
        std::mem::discriminant(self.0).hash(state);
        match self.0 {
            Value::Str(s) => s.hash(state),
            Value::Bytes(b) => b.hash(state),
            Value::Deferred(s) => s.hash(state),
            Value::Tuple(items) | Value::FrozenSet(items) => {
                items.len().hash(state);
                for it in items {
                    KeyRef(it).hash(state);
                }
            }
            _ => {}
        }
    }
}

impl PartialEq for KeyRef<'_> {
    fn eq(&self, other: &Self) -> bool {
        if let (Some(a), Some(b)) = (num_key(self.0), num_key(other.0)) {
            return a == b && !matches!(self.0, Value::Float(f) if f.is_nan());
        }
        match (self.0, other.0) {
            (Value::None, Value::None) => true,
            (Value::Str(a), Value::Str(b)) => a == b,
            (Value::Bytes(a), Value::Bytes(b)) => a == b,
            (Value::Deferred(a), Value::Deferred(b)) => a == b,
            // Frozensets compare element by element in pickle order (a documented shortcut).
            (Value::Tuple(a), Value::Tuple(b)) | (Value::FrozenSet(a), Value::FrozenSet(b)) => {
                a.len() == b.len() && a.iter().zip(b).all(|(x, y)| KeyRef(x) == KeyRef(y))
            }
            _ => false,
        }
    }
}

impl Eq for KeyRef<'_> {}

fn dedupe_dict(pairs: Vec<(Value, Value)>) -> StepResult<Vec<(Value, Value)>> {
    for (k, _) in &pairs {
        check_hashable(k)?;
    }
    let mut first: HashMap<KeyRef<'_>, usize> = HashMap::with_capacity(pairs.len());
    let mut target: Vec<usize> = Vec::with_capacity(pairs.len());
    for (i, (k, _)) in pairs.iter().enumerate() {
        let pos = *first.entry(KeyRef(k)).or_insert(i);
        target.push(pos);
    }
    if target.iter().enumerate().all(|(i, &t)| i == t) {
        return Ok(pairs);
    }
    drop(first);
    // Python keeps the first key's position and the last value.
    let mut out: Vec<Option<(Value, Value)>> = Vec::with_capacity(pairs.len());
    for (i, (k, v)) in pairs.into_iter().enumerate() {
        let t = target[i];
        if t == i {
            out.push(Some((k, v)));
        } else {
            out.push(None);
            if let Some(Some(slot)) = out.get_mut(t) {
                slot.1 = v;
            }
        }
    }
    Ok(out.into_iter().flatten().collect())
}

fn dedupe_set(items: Vec<Value>) -> StepResult<Vec<Value>> {
    for it in &items {
        check_hashable(it)?;
    }
    let mut seen: HashMap<KeyRef<'_>, ()> = HashMap::with_capacity(items.len());
    let keep: Vec<bool> = items
        .iter()
        .map(|it| seen.insert(KeyRef(it), ()).is_none())
        .collect();
    drop(seen);
    if keep.iter().all(|&k| k) {
        return Ok(items);
    }
    Ok(items
        .into_iter()
        .zip(keep)
        .filter_map(|(it, k)| k.then_some(it))
        .collect())
}

// ---------------------------------------------------------------------------------------------
// Decoding helpers
// ---------------------------------------------------------------------------------------------

fn pairs_of(items: Vec<Id>) -> StepResult<Vec<(Id, Id)>> {
    if items.len() % 2 != 0 {
        return invalid(format!(
            "odd number of items ({}) for key-value pairs",
            items.len()
        ));
    }
    Ok(items.chunks_exact(2).map(|c| (c[0], c[1])).collect())
}

fn parse_memo_key(line: &[u8]) -> StepResult<u64> {
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
fn latin1(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| char::from(b)).collect()
}

/// latin-1 encoding; fails on code points above U+00FF.
fn latin1_bytes(s: &str) -> StepResult<Vec<u8>> {
    s.chars()
        .map(|c| u8::try_from(u32::from(c)))
        .collect::<Result<Vec<u8>, _>>()
        .or_else(|_| invalid("byte string holds a character above U+00FF (not latin-1)"))
}

/// An integer from little-endian two's-complement bytes (LONG1/LONG4).
fn int_from_le(mut bytes: Vec<u8>) -> Node {
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
fn parse_decimal_int(line: &[u8]) -> StepResult<Node> {
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
fn unquote_string(line: &[u8]) -> StepResult<Vec<u8>> {
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
fn raw_unicode_escape_decode(line: &[u8]) -> StepResult<String> {
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
fn parse_dtype(descr: &str) -> StepResult<Dtype> {
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
fn decode_elements(bytes: &[u8], dtype: Dtype, count: usize) -> StepResult<ArrayData> {
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
fn fortran_to_c(data: ArrayData, shape: &[usize]) -> ArrayData {
    fn permute<T: Clone>(v: Vec<T>, shape: &[usize]) -> Vec<T> {
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

// ---------------------------------------------------------------------------------------------
// Access
// ---------------------------------------------------------------------------------------------

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
