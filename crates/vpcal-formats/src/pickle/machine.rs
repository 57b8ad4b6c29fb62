//! The pickle stack machine: opcodes to a graph of nodes, with the allow-listed globals.

use std::borrow::Cow;
use std::collections::HashMap;
use std::io::{self, BufRead, Read};

use super::convert::*;
use super::decode::*;
use super::node::*;
use super::value::*;

/// Reader with a byte position; allocations grow only with bytes actually read.
pub(super) struct Input<R: BufRead> {
    pub(super) r: R,
    pub(super) pos: u64,
}

impl<R: BufRead> Input<R> {
    pub(super) fn io_err(&self, e: io::Error) -> (u64, ErrorKind) {
        (self.pos, ErrorKind::Io(e))
    }

    pub(super) fn next_byte(&mut self) -> Result<Option<u8>, (u64, ErrorKind)> {
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

    pub(super) fn read_vec(&mut self, n: u64, what: &str) -> Result<Vec<u8>, (u64, ErrorKind)> {
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

    pub(super) fn read_array<const N: usize>(
        &mut self,
        what: &str,
    ) -> Result<[u8; N], (u64, ErrorKind)> {
        let v = self.read_vec(N as u64, what)?;
        let mut out = [0u8; N];
        out.copy_from_slice(&v);
        Ok(out)
    }

    pub(super) fn skip(&mut self, n: u64, what: &str) -> Result<(), (u64, ErrorKind)> {
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
    pub(super) fn read_line(&mut self, what: &str) -> Result<Vec<u8>, (u64, ErrorKind)> {
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

pub(super) struct Machine<R: BufRead> {
    pub(super) input: Input<R>,
    pub(super) options: LoadOptions,
    /// Total input length when known (for the size budget); otherwise bytes read so far.
    pub(super) known_len: Option<u64>,
    pub(super) nodes: Vec<Node>,
    pub(super) stack: Vec<Id>,
    pub(super) marks: Vec<usize>,
    pub(super) memo: Memo,
}

/// The memo: dense for the small, sequential keys picklers write; sparse beyond.
#[derive(Debug, Default)]
pub(super) struct Memo {
    /// `dense[key]` = node id + 1 (0: empty).
    pub(super) dense: Vec<u32>,
    pub(super) sparse: HashMap<u64, Id>,
    /// Distinct keys stored (what `MEMOIZE` uses as the next key).
    pub(super) count: u64,
}

impl Memo {
    /// Store `id` under `key`; keys below `dense_limit` use the dense table (its memory is then
    /// bounded by the caller's limit).
    pub(super) fn put(&mut self, key: u64, id: Id, dense_limit: u64) {
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

    pub(super) fn get(&self, key: u64) -> Option<Id> {
        let dense = usize::try_from(key)
            .ok()
            .and_then(|k| self.dense.get(k))
            .filter(|&&slot| slot != 0)
            .map(|&slot| slot as usize - 1);
        dense.or_else(|| self.sparse.get(&key).copied())
    }
}

impl<R: BufRead> Machine<R> {
    pub(super) fn new(r: R, options: LoadOptions, known_len: Option<u64>) -> Self {
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

    pub(super) fn run(mut self) -> Result<Value, PickleError> {
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
    pub(super) fn location(&self) -> Option<String> {
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

    pub(super) fn floor(&self) -> usize {
        self.marks.last().copied().unwrap_or(0)
    }

    pub(super) fn push_node(&mut self, node: Node) -> Id {
        self.nodes.push(node);
        let id = self.nodes.len() - 1;
        self.stack.push(id);
        id
    }

    pub(super) fn pop(&mut self) -> StepResult<Id> {
        if self.stack.len() <= self.floor() {
            return invalid("stack underflow");
        }
        match self.stack.pop() {
            Some(id) => Ok(id),
            None => invalid("stack underflow"),
        }
    }

    pub(super) fn top(&self) -> StepResult<Id> {
        if self.stack.len() <= self.floor() {
            return invalid("stack underflow");
        }
        match self.stack.last() {
            Some(&id) => Ok(id),
            None => invalid("stack underflow"),
        }
    }

    pub(super) fn pop_mark(&mut self) -> StepResult<Vec<Id>> {
        let Some(mark) = self.marks.pop() else {
            return invalid("no MARK on the stack");
        };
        if mark > self.stack.len() {
            return invalid("corrupt MARK");
        }
        Ok(self.stack.split_off(mark))
    }

    pub(super) fn node(&self, id: Id) -> StepResult<&Node> {
        match self.nodes.get(id) {
            Some(n) => Ok(n),
            None => invalid("internal: dangling node id"),
        }
    }

    pub(super) fn node_mut(&mut self, id: Id) -> StepResult<&mut Node> {
        match self.nodes.get_mut(id) {
            Some(n) => Ok(n),
            None => invalid("internal: dangling node id"),
        }
    }

    pub(super) fn io<T>(&mut self, r: Result<T, (u64, ErrorKind)>) -> StepResult<T> {
        r.map_err(|(_, kind)| kind)
    }

    pub(super) fn read_line(&mut self, what: &str) -> StepResult<Vec<u8>> {
        let r = self.input.read_line(what);
        self.io(r)
    }

    pub(super) fn read_vec(&mut self, n: u64, what: &str) -> StepResult<Vec<u8>> {
        let r = self.input.read_vec(n, what);
        self.io(r)
    }

    pub(super) fn read_u8(&mut self, what: &str) -> StepResult<u8> {
        let r = self.input.read_array::<1>(what);
        Ok(self.io(r)?[0])
    }

    pub(super) fn read_u16(&mut self, what: &str) -> StepResult<u16> {
        let r = self.input.read_array::<2>(what);
        Ok(u16::from_le_bytes(self.io(r)?))
    }

    pub(super) fn read_u32(&mut self, what: &str) -> StepResult<u32> {
        let r = self.input.read_array::<4>(what);
        Ok(u32::from_le_bytes(self.io(r)?))
    }

    pub(super) fn read_i32(&mut self, what: &str) -> StepResult<i32> {
        let r = self.input.read_array::<4>(what);
        Ok(i32::from_le_bytes(self.io(r)?))
    }

    pub(super) fn read_u64(&mut self, what: &str) -> StepResult<u64> {
        let r = self.input.read_array::<8>(what);
        Ok(u64::from_le_bytes(self.io(r)?))
    }

    /// A byte-string payload of `n` bytes that may be deferred.
    pub(super) fn byte_payload(
        &mut self,
        n: u64,
        what: &str,
    ) -> StepResult<Result<Vec<u8>, ByteSpan>> {
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

    pub(super) fn len_to_u64(n: i64, what: &str) -> StepResult<u64> {
        u64::try_from(n).or_else(|_| invalid(format!("{what} has negative length {n}")))
    }

    // --- one opcode -----------------------------------------------------------------------

    /// Execute one opcode; `Ok(true)` at STOP.
    pub(super) fn step(&mut self, op: u8) -> StepResult<bool> {
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

    pub(super) fn push_utf8(&mut self, n: u64, what: &str) -> StepResult<()> {
        let bytes = self.read_vec(n, what)?;
        match String::from_utf8(bytes) {
            Ok(s) => {
                self.push_node(Node::Str(s));
                Ok(())
            }
            Err(e) => invalid(format!("{what} is not valid UTF-8: {}", e.utf8_error())),
        }
    }

    pub(super) fn push_bytes(&mut self, n: u64, what: &str) -> StepResult<()> {
        let node = match self.byte_payload(n, what)? {
            Ok(bytes) => Node::Bytes(bytes),
            Err(span) => Node::Deferred(span),
        };
        self.push_node(node);
        Ok(())
    }

    /// Memo keys below this go to the dense table: picklers number memoized objects
    /// sequentially, so real keys stay below the number of objects built.
    pub(super) fn dense_memo_limit(&self) -> u64 {
        self.nodes.len() as u64 + 1024
    }

    pub(super) fn get_memo(&mut self, key: u64) -> StepResult<()> {
        match self.memo.get(key) {
            Some(id) => {
                self.stack.push(id);
                Ok(())
            }
            None => invalid(format!("memo key {key} was never stored")),
        }
    }

    pub(super) fn push_global(&mut self, module: String, name: String) -> StepResult<()> {
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

    pub(super) fn call(&mut self, func: Id, args: &[Id]) -> StepResult<Node> {
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

    pub(super) fn build(&mut self, target: Id, state: Id) -> StepResult<()> {
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

    pub(super) fn tuple_items(&self, id: Id, what: &str) -> StepResult<Vec<Id>> {
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
    pub(super) fn dtype_state(&self, target: Id, state: Id) -> StepResult<Dtype> {
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
    pub(super) fn array_state(&self, state: Id) -> StepResult<(Vec<usize>, Dtype, Body)> {
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

    pub(super) fn finish(mut self, root: Id) -> StepResult<Value> {
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
