//! The machine's graph: nodes, their ids, the allow-listed callables, and the step result.

use super::value::*;

pub(super) type Id = usize;

pub(super) const ID_NONE: Id = 0;
pub(super) const ID_FALSE: Id = 1;
pub(super) const ID_TRUE: Id = 2;

/// Allowed callables, re-implemented.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Callable {
    Reconstruct,
    NdarrayType,
    Dtype,
    Scalar,
    Set,
    FrozenSet,
    CodecsEncode,
    Bytes,
}

pub(super) fn resolve_global(module: &str, name: &str) -> Option<Callable> {
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
pub(super) struct GlobalRef {
    pub(super) callable: Callable,
    pub(super) module: String,
    pub(super) name: String,
}

/// Array data as held by the machine: objects are still node ids.
#[derive(Debug)]
pub(super) enum Body {
    Typed(ArrayData),
    Objects(Vec<Id>),
}

#[derive(Debug)]
pub(super) struct ArrayNode {
    /// `None` until `BUILD` gives the state.
    pub(super) built: Option<(Vec<usize>, Dtype, Body)>,
}

#[derive(Debug)]
pub(super) enum Node {
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
    pub(super) fn type_name(&self) -> &'static str {
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

pub(super) type StepResult<T> = Result<T, ErrorKind>;

pub(super) fn invalid<T>(msg: impl Into<String>) -> StepResult<T> {
    Err(ErrorKind::Invalid(msg.into()))
}
