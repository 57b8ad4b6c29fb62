//! The safe pickle reader against Python's own `pickle`: fixtures of every protocol written by
//! `scripts/pickle_fixtures.py`, the real BrnoCompSpeed `gt_data.pkl` files (when present),
//! refused globals, truncations and hostile input.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use vpcal_formats::pickle::{self, ArrayData, ErrorKind, LoadOptions, NdArray, Value};

fn fixtures_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/pickle")
}

fn data_dir() -> PathBuf {
    std::env::var_os("VPCAL_DATA").map_or_else(
        || PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")),
        PathBuf::from,
    )
}

/// All `*.pkl` fixtures with their expected canonical text.
fn fixtures() -> Vec<(String, Vec<u8>, String)> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(fixtures_dir()).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "pkl") {
            let canon = std::fs::read_to_string(path.with_extension("canon")).unwrap();
            let name = path.file_stem().unwrap().to_string_lossy().into_owned();
            out.push((
                name,
                std::fs::read(&path).unwrap(),
                canon.trim_end().to_string(),
            ));
        }
    }
    out.sort();
    assert!(
        out.len() >= 15,
        "fixtures missing: run scripts/pickle_fixtures.py"
    );
    out
}

// --- canonical text, exactly as scripts/pickle_fixtures.py writes it ---------------------------

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn canon_f64(f: f64) -> String {
    format!("f{:016x}", f.to_bits())
}

fn canon_elements(a: &NdArray) -> Vec<String> {
    let d = &a.data;
    (0..d.len())
        .map(|i| match d {
            ArrayData::Object(items) => canon(&items[i]),
            ArrayData::Bool(v) => if v[i] { "T" } else { "F" }.to_string(),
            ArrayData::F32(_) | ArrayData::F64(_) => canon_f64(d.get_f64(i).unwrap()),
            ArrayData::U64(v) => format!("i{}", v[i]),
            _ => format!("i{}", d.get_i64(i).unwrap()),
        })
        .collect()
}

fn kind(a: &NdArray) -> String {
    let descr = a.dtype.descr();
    descr[1..].to_string()
}

fn canon(v: &Value) -> String {
    match v {
        Value::None => "N".into(),
        Value::Bool(b) => if *b { "T" } else { "F" }.into(),
        Value::Int(_) | Value::BigInt(_) => format!("i{}", v.to_decimal_string().unwrap()),
        Value::Float(f) => canon_f64(*f),
        Value::Str(s) => format!("s{}", hex(s.as_bytes())),
        Value::Bytes(b) => format!("b{}", hex(b)),
        Value::Deferred(_) => panic!("deferred data in a canonical text"),
        Value::List(items) => format!(
            "[{}]",
            items.iter().map(canon).collect::<Vec<_>>().join(",")
        ),
        Value::Tuple(items) => format!(
            "({})",
            items.iter().map(canon).collect::<Vec<_>>().join(",")
        ),
        Value::Dict(pairs) => format!(
            "{{{}}}",
            pairs
                .iter()
                .map(|(k, v)| format!("{}:{}", canon(k), canon(v)))
                .collect::<Vec<_>>()
                .join(",")
        ),
        Value::Set(items) | Value::FrozenSet(items) => {
            let mut parts: Vec<String> = items.iter().map(canon).collect();
            parts.sort();
            let tag = if matches!(v, Value::Set(_)) {
                "set"
            } else {
                "fset"
            };
            format!("{tag}{{{}}}", parts.join(","))
        }
        Value::Array(a) => {
            let shape: String = a.shape.iter().map(|d| format!("{d},")).collect();
            format!("nd{}({shape})[{}]", kind(a), canon_elements(a).join(","))
        }
        Value::Scalar(a) => format!("sc{}[{}]", kind(a), canon_elements(a).join(",")),
    }
}

fn fnv1a64(text: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

// --- fixtures ---------------------------------------------------------------------------------

#[test]
fn every_fixture_matches_python() {
    for (name, bytes, expected) in fixtures() {
        let v = pickle::from_slice(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(
            canon(&v),
            expected,
            "{name}: from_slice differs from Python"
        );
        let v = pickle::from_reader(bytes.as_slice()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(
            canon(&v),
            expected,
            "{name}: from_reader differs from Python"
        );
    }
}

#[test]
fn python2_and_python3_pickles_agree_on_values() {
    let a = pickle::from_path(
        &fixtures_dir().join("rich_py2_p2.pkl"),
        &LoadOptions::default(),
    )
    .unwrap();
    let b = pickle::from_path(
        &fixtures_dir().join("rich_py3_p4.pkl"),
        &LoadOptions::default(),
    )
    .unwrap();
    // Python-2 byte strings decode as latin-1 text, Python-3 bytes stay bytes; the arrays match.
    assert_eq!(a.get("arrays"), b.get("arrays"));
    assert_eq!(a.get("scalars"), b.get("scalars"));
    assert_eq!(
        a.get("bytes").unwrap().as_byte_string(),
        b.get("bytes").unwrap().as_byte_string()
    );
}

#[test]
fn typed_access_with_paths() {
    let v = pickle::from_slice(&std::fs::read(fixtures_dir().join("rich_py2_p2.pkl")).unwrap())
        .unwrap();
    let root = v.view();
    let arrays = root.get("arrays").unwrap();
    let (shape, data) = arrays.get("f8").unwrap().as_array_f64().unwrap();
    assert_eq!(shape, vec![2, 3]);
    assert_eq!(data, vec![0.0, 1.5, 3.0, 4.5, 6.0, 7.5]);
    // Fortran order is decoded to C order.
    let (shape, data) = arrays.get("fortran").unwrap().as_array_f64().unwrap();
    assert_eq!(shape, vec![2, 3, 4]);
    assert_eq!(data, (0..24).map(f64::from).collect::<Vec<_>>());
    assert_eq!(
        arrays.get("f8_be").unwrap().as_f64_array::<3>().unwrap(),
        [1.0, 2.5, -0.125]
    );
    assert_eq!(
        root.get("scalars")
            .unwrap()
            .at(0)
            .unwrap()
            .as_f64()
            .unwrap(),
        1.25
    );
    assert_eq!(
        root.get("scalars")
            .unwrap()
            .at(2)
            .unwrap()
            .as_i64()
            .unwrap(),
        -7
    );
    assert!(root
        .get("scalars")
        .unwrap()
        .at(5)
        .unwrap()
        .as_bool()
        .unwrap());
    assert_eq!(root.get("str").unwrap().as_str().unwrap(), "hello");
    assert_eq!(v.get_int(42).unwrap().as_str(), Some("int key"));
    assert_eq!(v.get_int(-5).unwrap().as_str(), Some("negative int key"));

    let err = root
        .get("nested")
        .unwrap()
        .get("list")
        .unwrap()
        .at(1)
        .unwrap()
        .at(7)
        .unwrap_err();
    assert_eq!(err.path, r#"["nested"]["list"][1]"#);
    assert!(err.to_string().contains("list of 2 items"), "{err}");
    let err = root.get("str").unwrap().as_f64().unwrap_err();
    assert_eq!(
        err.to_string(),
        r#"at ["str"]: expected a number, found str "hello""#
    );
    let err = root.get("missing").unwrap_err();
    assert!(
        err.to_string()
            .contains(r#"expected a dict with key "missing""#),
        "{err}"
    );
}

#[test]
fn deferred_byte_strings_point_into_the_file() {
    let path = fixtures_dir().join("rich_py2_p2.pkl");
    let opts = LoadOptions {
        defer_bytes_over: Some(400),
    };
    let v = pickle::from_path(&path, &opts).unwrap();
    let full = pickle::from_path(&path, &LoadOptions::default()).unwrap();
    let mut file = std::fs::File::open(&path).unwrap();

    let Value::Deferred(span) = v.get("long_bytes").unwrap() else {
        panic!("long_bytes not deferred: {:?}", v.get("long_bytes"));
    };
    let expected = full
        .get("long_bytes")
        .unwrap()
        .as_byte_string()
        .unwrap()
        .into_owned();
    assert_eq!(span.read_from(&mut file).unwrap(), expected);

    let big = v
        .get("arrays")
        .unwrap()
        .get("big")
        .unwrap()
        .as_array()
        .unwrap();
    let ArrayData::Deferred {
        span,
        fortran_order,
    } = big.data
    else {
        panic!("big array not deferred");
    };
    assert!(!fortran_order);
    let raw = span.read_from(&mut file).unwrap();
    let decoded: Vec<f64> = raw
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let (_, expected) = full
        .get("arrays")
        .unwrap()
        .get("big")
        .unwrap()
        .as_array_f64()
        .unwrap();
    assert_eq!(decoded, expected);
    // Small strings are still inline.
    assert_eq!(v.get("str").unwrap().as_str(), Some("hello"));
}

// --- real data --------------------------------------------------------------------------------

#[test]
fn every_real_gt_data_matches_python() {
    let base = data_dir().join("bcs/dataset");
    if !base.is_dir() {
        eprintln!(
            "SKIP: no BrnoCompSpeed data at {} (set VPCAL_DATA)",
            base.display()
        );
        return;
    }
    let expected: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(fixtures_dir().join("gt_data_expected.json")).unwrap(),
    )
    .unwrap();
    let expected = expected.as_object().unwrap();
    assert_eq!(expected.len(), 12);
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs().max(1.0);
    for (session, exp) in expected {
        let path = base.join(session).join("gt_data.pkl");
        let gt =
            pickle::from_path(&path, &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            fnv1a64(&canon(&gt)),
            exp["fnv1a64"].as_str().unwrap(),
            "{session}: content differs from Python's pickle"
        );
        let g = gt.view();
        let keys: Vec<&str> = gt
            .as_dict()
            .unwrap()
            .iter()
            .map(|(k, _)| k.as_str().unwrap())
            .collect();
        let exp_keys: Vec<&str> = exp["keys"]
            .as_array()
            .unwrap()
            .iter()
            .map(|k| k.as_str().unwrap())
            .collect();
        assert_eq!(keys, exp_keys, "{session}");
        assert!(close(
            g.get("fps").unwrap().as_f64().unwrap(),
            exp["fps"].as_f64().unwrap()
        ));
        let dm = g.get("distanceMeasurement").unwrap().items().unwrap();
        assert_eq!(
            dm.len() as u64,
            exp["distance_measurements"].as_u64().unwrap()
        );
        assert!(close(
            dm[0].get("distance").unwrap().as_f64().unwrap(),
            exp["dm0_distance"].as_f64().unwrap()
        ));
        let p1 = dm[0].get("p1").unwrap().as_f64_array::<3>().unwrap();
        for (a, b) in p1.iter().zip(exp["dm0_p1"].as_array().unwrap()) {
            assert!(close(*a, b.as_f64().unwrap()), "{session}: p1 {p1:?}");
        }
        let last = dm.last().unwrap();
        let p2 = last.get("p2").unwrap().as_f64_array::<3>().unwrap();
        for (a, b) in p2.iter().zip(exp["dm_last_p2"].as_array().unwrap()) {
            assert!(close(*a, b.as_f64().unwrap()), "{session}: p2 {p2:?}");
        }
        assert_eq!(
            last.get("toVP1").unwrap().as_bool().unwrap(),
            exp["dm_last_toVP1"].as_bool().unwrap()
        );
        let cars = g.get("cars").unwrap().items().unwrap();
        assert_eq!(cars.len() as u64, exp["cars"].as_u64().unwrap());
        assert!(close(
            cars[0].get("speed").unwrap().as_f64().unwrap(),
            exp["car0_speed"].as_f64().unwrap()
        ));
        let mut lanes: Vec<i64> = cars[0]
            .get("laneIndex")
            .unwrap()
            .as_set()
            .unwrap()
            .iter()
            .map(|x| x.as_i64().unwrap())
            .collect();
        lanes.sort_unstable();
        let exp_lanes: Vec<i64> = exp["car0_lane_index"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_i64().unwrap())
            .collect();
        assert_eq!(lanes, exp_lanes, "{session}");
        assert_eq!(
            cars.last().unwrap().get("carId").unwrap().as_i64().unwrap(),
            exp["car_last_id"].as_i64().unwrap()
        );
        let valid = cars
            .iter()
            .filter(|c| c.get("valid").unwrap().as_bool().unwrap())
            .count();
        assert_eq!(
            valid as u64,
            exp["valid_cars"].as_u64().unwrap(),
            "{session}"
        );
        let mut invalid: Vec<i64> = g
            .get("invalidLanes")
            .unwrap()
            .as_set()
            .unwrap()
            .iter()
            .map(|x| x.as_i64().unwrap())
            .collect();
        invalid.sort_unstable();
        let exp_invalid: Vec<i64> = exp["invalid_lanes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_i64().unwrap())
            .collect();
        assert_eq!(invalid, exp_invalid, "{session}");
        assert_eq!(
            g.get("measurementLines").unwrap().items().unwrap().len() as u64,
            exp["measurement_lines"].as_u64().unwrap()
        );
        let line = g
            .get("laneDivLines")
            .unwrap()
            .at(0)
            .unwrap()
            .as_f64_array::<3>()
            .unwrap();
        for (a, b) in line.iter().zip(exp["lane_div_line0"].as_array().unwrap()) {
            assert!(
                close(*a, b.as_f64().unwrap()),
                "{session}: lane line {line:?}"
            );
        }
    }
}

// --- refused and hostile input ----------------------------------------------------------------

#[test]
fn forbidden_globals_are_refused_by_name() {
    let cases: &[(&[u8], &str)] = &[
        (b"cos\nsystem\n(S'echo owned'\ntR.", "os.system"),
        (
            b"\x80\x02cposix\nsystem\nq\x00U\x02idq\x01\x85q\x02Rq\x03.",
            "posix.system",
        ),
        (
            b"\x80\x04\x8c\x08builtins\x8c\x04eval\x93\x8c\x041+1\x85R.",
            "builtins.eval",
        ),
        (b"(S'ls'\nisubprocess\nPopen\n.", "subprocess.Popen"),
        (
            b"\x80\x02ccopy_reg\n_reconstructor\n.",
            "copy_reg._reconstructor",
        ),
        (b"\x80\x02cnumpy\nload\n.", "numpy.load"),
        (
            b"\x80\x02cnumpy.core.multiarray\n_reconstruct_evil\n.",
            "numpy.core.multiarray._reconstruct_evil",
        ),
    ];
    for (bytes, name) in cases {
        let err = pickle::from_slice(bytes).unwrap_err();
        assert!(err.is_forbidden_global(), "{name}: {err}");
        let msg = err.to_string();
        assert!(
            msg.contains(&format!("refusing to load global {name}")),
            "{msg}"
        );
        assert!(msg.contains("byte ") && msg.contains("(opcode "), "{msg}");
    }
    let err = pickle::from_path(&fixtures_dir().join("missing.pkl"), &LoadOptions::default())
        .unwrap_err();
    assert!(err.to_string().contains("missing.pkl"), "{err}");
}

#[test]
fn every_truncation_of_every_fixture_is_an_error() {
    let fixtures = fixtures();
    std::thread::scope(|s| {
        for (name, bytes, _) in &fixtures {
            s.spawn(move || {
                for cut in 0..bytes.len() {
                    match pickle::from_slice(&bytes[..cut]) {
                        Ok(v) => panic!("{name} cut at {cut} parsed as {v:?}"),
                        Err(e) => assert!(
                            matches!(e.kind, ErrorKind::Truncated(_)),
                            "{name} cut at {cut}: not reported as truncated: {e}"
                        ),
                    }
                }
            });
        }
    });
}

#[test]
fn exponential_sharing_is_refused() {
    // x = None; then 60 times: x = [x, x]  (2^60 values once shared references are copied)
    let mut p = b"\x80\x02Nq\x00".to_vec();
    for _ in 0..60 {
        p.extend_from_slice(b"(h\x00h\x00lq\x00");
    }
    p.push(b'.');
    let err = pickle::from_slice(&p).unwrap_err();
    assert!(matches!(err.kind, ErrorKind::TooLarge(_)), "{err}");
}

#[test]
fn deep_nesting_and_self_reference_are_refused() {
    let mut deep = b"\x80\x02".to_vec();
    deep.extend(std::iter::repeat_n(b']', 100_000));
    deep.extend(std::iter::repeat_n(b'a', 99_999));
    deep.push(b'.');
    let err = pickle::from_slice(&deep).unwrap_err();
    assert!(matches!(err.kind, ErrorKind::TooDeep), "{err}");

    let cyclic = b"\x80\x02]q\x00h\x00a.";
    let err = pickle::from_slice(cyclic).unwrap_err();
    assert!(err.to_string().contains("self-referencing"), "{err}");
}

#[test]
fn huge_length_claims_do_not_allocate() {
    let cases: &[&[u8]] = &[
        b"\x80\x04\x8d\xff\xff\xff\xff\xff\xff\xff\x7fabc",
        b"\x80\x04\x8e\xff\xff\xff\xff\xff\xff\xff\xff",
        b"\x80\x02T\xff\xff\xff\x7fxyz",
        b"\x80\x02\x8b\xff\xff\xff\x7f\x01",
        b"X\xff\xff\xff\xff",
    ];
    for c in cases {
        let err = pickle::from_slice(c).unwrap_err();
        assert!(matches!(err.kind, ErrorKind::Truncated(_)), "{err}");
    }
    let neg = pickle::from_slice(b"\x80\x02T\xff\xff\xff\xff.").unwrap_err();
    assert!(neg.to_string().contains("negative length"), "{neg}");
}

#[test]
fn numpy_shape_must_match_the_data() {
    // _reconstruct + BUILD with a shape of 2^62 x 2^62 elements and 8 bytes of data.
    let p = b"\x80\x02cnumpy.core.multiarray\n_reconstruct\ncnumpy\nndarray\nK\x00\x85U\x01b\x87R(K\x01\x8a\x08\x00\x00\x00\x00\x00\x00\x00\x40\x8a\x08\x00\x00\x00\x00\x00\x00\x00\x40\x86cnumpy\ndtype\nU\x02f8\x89\x88\x87R(K\x03U\x01<NNNJ\xff\xff\xff\xffJ\xff\xff\xff\xffK\x00tb\x89U\x08\x00\x00\x00\x00\x00\x00\xf0?tb.";
    let err = pickle::from_slice(p).unwrap_err();
    assert!(err.to_string().contains("overflows"), "{err}");
    let ok = b"\x80\x02cnumpy.core.multiarray\n_reconstruct\ncnumpy\nndarray\nK\x00\x85U\x01b\x87R(K\x01K\x01\x85cnumpy\ndtype\nU\x02f8\x89\x88\x87R(K\x03U\x01<NNNJ\xff\xff\xff\xffJ\xff\xff\xff\xffK\x00tb\x89U\x08\x00\x00\x00\x00\x00\x00\xf0?tb.";
    let v = pickle::from_slice(ok).unwrap();
    assert_eq!(v.as_array_f64(), Some((vec![1], vec![1.0])));
    let mut short = ok.to_vec();
    let pos = short.windows(2).position(|w| w == b"U\x08").unwrap();
    short[pos + 1] = 7;
    short.remove(pos + 2);
    let err = pickle::from_slice(&short).unwrap_err();
    assert!(err.to_string().contains("needs 8 bytes, found 7"), "{err}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        let _ = pickle::from_slice(&bytes);
        let mut with_proto = vec![0x80, 2];
        with_proto.extend_from_slice(&bytes);
        let _ = pickle::from_slice(&with_proto);
    }

    #[test]
    fn mutated_fixtures_never_panic(
        which in 0usize..8,
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
    ) {
        let names = ["rich_py2_p0", "rich_py2_p1", "rich_py2_p2", "rich_py3_p0",
                     "rich_py3_p2", "rich_py3_p4", "edge_text", "edge_proto4"];
        let mut bytes = std::fs::read(fixtures_dir().join(format!("{}.pkl", names[which]))).unwrap();
        for (at, b) in edits {
            let i = at.index(bytes.len());
            bytes[i] = b;
        }
        let _ = pickle::from_slice(&bytes);
    }
}

#[test]
fn errors_locate_the_element_being_built() {
    let path = fixtures_dir().join("rich_py2_p2.pkl");
    let bytes = std::fs::read(&path).unwrap();
    let opts = LoadOptions {
        defer_bytes_over: Some(400),
    };
    let v = pickle::from_path(&path, &opts).unwrap();
    let big = v
        .get("arrays")
        .unwrap()
        .get("big")
        .unwrap()
        .as_array()
        .unwrap();
    let ArrayData::Deferred { span, .. } = big.data else {
        panic!("big array not deferred");
    };
    let cut = usize::try_from(span.offset).unwrap() + 100;
    let err = pickle::from_slice(&bytes[..cut]).unwrap_err();
    assert_eq!(
        err.location.as_deref(),
        Some(r#"["arrays"]["big"]"#),
        "{err}"
    );
    assert!(
        err.to_string()
            .contains(r#"in ["arrays"]["big"]: truncated pickle"#),
        "{err}"
    );

    // Cut inside the list of ints: the fourth element (255, BININT1) is being read.
    let ints_at = bytes.windows(6).position(|w| w == b"U\x04ints").unwrap();
    let err = pickle::from_slice(&bytes[..ints_at + 22]).unwrap_err();
    assert_eq!(err.location.as_deref(), Some(r#"["ints"][3]"#), "{err}");
}

#[test]
fn huge_integers_load_but_are_not_printed() {
    // LONG4 with 100 kB of magnitude: loads in linear time; decimal text is refused like
    // Python's str() beyond 4300 digits (the conversion is quadratic).
    let n = 100_000u32;
    let mut p = b"\x80\x02\x8b".to_vec();
    p.extend_from_slice(&n.to_le_bytes());
    p.extend(std::iter::repeat_n(0x11u8, n as usize));
    p.push(b'.');
    let v = pickle::from_slice(&p).unwrap();
    assert!(matches!(&v, Value::BigInt(b) if b.len() == n as usize));
    assert_eq!(v.to_decimal_string(), None);
    let small =
        pickle::from_slice(b"\x80\x02\x8a\x09\x00\x00\x00\x00\x00\x00\x00\x00\x01.").unwrap();
    assert_eq!(
        small.to_decimal_string().as_deref(),
        Some("18446744073709551616")
    );
}

#[test]
fn memo_keys_far_beyond_the_input_still_work() {
    // LONG_BINPUT/LONG_BINGET with key 2^32 - 1 (sparse table), then MEMOIZE (next key = 1
    // distinct key stored so far) and BINGET 1. Python's pure-Python unpickler
    // (`pickle._Unpickler`) returns ([], 7, 'a'); its C unpickler runs out of memory on the key.
    let p = b"\x80\x04]r\xff\xff\xff\xff0K\x07\x94\x8c\x01a\x94(j\xff\xff\xff\xffh\x01h\x02t.";
    let v = pickle::from_slice(p).unwrap();
    assert_eq!(
        v,
        Value::Tuple(vec![
            Value::List(vec![]),
            Value::Int(7),
            Value::Str("a".into())
        ])
    );
}
