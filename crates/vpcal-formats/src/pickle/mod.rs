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

use std::io::{BufReader, Read};
use std::path::Path;

mod access;
mod convert;
mod decode;
mod machine;
mod node;
mod value;

pub use access::{AccessError, View};
use machine::Machine;
pub use value::*;

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
