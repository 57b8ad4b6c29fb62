//! Fuzz the safe pickle reader: any input must give a value or an error, never a panic, a hang
//! or unbounded memory. Both entry points run (slice and buffered stream, the latter with byte
//! strings deferred), and a successful load must survive the accessors used by callers.
#![no_main]

use libfuzzer_sys::fuzz_target;
use vpcal_formats::pickle::{self, LoadOptions, Value};

fn touch(v: &Value, depth: usize) {
    if depth > 8 {
        return;
    }
    let _ = (
        v.as_f64(),
        v.as_i64(),
        v.as_bool(),
        v.as_byte_string(),
        v.as_array_f64(),
    );
    let _ = (v.describe(), v.to_decimal_string(), v.get("p1"), v.at(0));
    let view = v.view();
    let _ = (
        view.as_f64_array::<3>(),
        view.get("cars"),
        view.items(),
        view.entries(),
    );
    if let Some(items) = v.as_list().or(v.as_set()) {
        for it in items.iter().take(16) {
            touch(it, depth + 1);
        }
    }
    if let Some(pairs) = v.as_dict() {
        for (k, x) in pairs.iter().take(16) {
            touch(k, depth + 1);
            touch(x, depth + 1);
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let a = pickle::from_slice(data);
    if let Ok(v) = &a {
        touch(v, 0);
    }
    let opts = LoadOptions {
        defer_bytes_over: Some(16),
    };
    if let Ok(v) = pickle::from_reader_with(data, &opts) {
        touch(&v, 0);
    }
    let c = pickle::from_reader(data);
    assert_eq!(a.is_ok(), c.is_ok(), "from_slice and from_reader disagree");
    if let (Ok(x), Ok(y)) = (&a, &c) {
        // NaN != NaN, so compare the debug text.
        assert_eq!(format!("{x:?}"), format!("{y:?}"));
    }
});
