//! From the machine's node graph to [`Value`]s: costs, cycles, dict and set semantics.

use std::collections::HashMap;
use std::hash::{Hash, Hasher};

use super::node::*;
use super::value::*;

/// `Converter::state` of a node not visited yet.
pub(super) const VISIT_NEW: u64 = u64::MAX;
/// `Converter::state` of a node whose children are being visited.
pub(super) const VISIT_IN_PROGRESS: u64 = u64::MAX - 1;
/// Expanded costs saturate below the two markers.
pub(super) const MAX_COST: u64 = u64::MAX - 2;

pub(super) struct Converter {
    /// Per node: [`VISIT_NEW`], [`VISIT_IN_PROGRESS`] or the expanded cost once visited.
    pub(super) state: Vec<u64>,
    /// Number of references to each node from the reachable graph.
    pub(super) refs: Vec<u32>,
    /// Converted values of shared nodes, with the number of uses left.
    pub(super) cache: HashMap<Id, (Value, u32)>,
}

pub(super) fn children(node: &Node) -> Box<dyn Iterator<Item = Id> + '_> {
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

pub(super) fn own_cost(node: &Node) -> u64 {
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
    pub(super) fn analyse(&mut self, nodes: &[Node], id: Id, depth: usize) -> StepResult<u64> {
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

    pub(super) fn build(&mut self, nodes: &mut [Node], id: Id) -> StepResult<Value> {
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

    pub(super) fn build_all(&mut self, nodes: &mut [Node], ids: &[Id]) -> StepResult<Vec<Value>> {
        ids.iter().map(|&id| self.build(nodes, id)).collect()
    }
}

/// Hash/equality of values as Python dict keys (1 == 1.0 == True; lists are unhashable).
pub(super) struct KeyRef<'a>(&'a Value);

/// A number as Python compares them: integral values as integers.
#[derive(PartialEq, Eq, Hash)]
pub(super) enum NumKey {
    Int(i64),
    Float(u64),
    Big(Vec<u8>),
}

pub(super) fn num_key(v: &Value) -> Option<NumKey> {
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

pub(super) fn check_hashable(v: &Value) -> StepResult<()> {
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

pub(super) fn dedupe_dict(pairs: Vec<(Value, Value)>) -> StepResult<Vec<(Value, Value)>> {
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

pub(super) fn dedupe_set(items: Vec<Value>) -> StepResult<Vec<Value>> {
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
