//! Parsers for flag values shared by the subcommands (`WxH` sizes, aggregation methods), with
//! messages that say what was expected.

/// `WxH` image size in pixels.
pub fn size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected an image size WxH (e.g. 1920x1080), got {s:?}"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| *v > 0)
            .ok_or_else(|| format!("expected an image size WxH with positive integers, got {s:?}"))
    };
    Ok((parse(w)?, parse(h)?))
}

/// `SHORT,LONG`: a focal-length range in pixels (`--focal-range`).
pub fn focal_range(s: &str) -> Result<[f64; 2], String> {
    let (a, b) = s.split_once(',').ok_or_else(|| {
        format!("expected the shortest and longest focal length SHORT,LONG in pixels, got {s:?}")
    })?;
    let parse = |v: &str| {
        v.trim()
            .parse::<f64>()
            .map_err(|_| format!("expected SHORT,LONG focal lengths in pixels, got {s:?}"))
    };
    let range = [parse(a)?, parse(b)?];
    vpcal::aggregate::check_focal_range(range)?;
    Ok(range)
}

/// Parser of `--method`: one of [`Method::NAMES`] (listed in `--help` and in errors).
pub fn method() -> impl clap::builder::TypedValueParser<Value = vpcal::aggregate::Method> {
    use clap::builder::TypedValueParser as _;
    clap::builder::PossibleValuesParser::new(vpcal::aggregate::Method::NAMES)
        .map(|s| s.parse().unwrap_or(vpcal::aggregate::Method::Robust))
}

/// A finite number above zero (focal lengths, distances, frame rates). Refused values exit
/// with the usage code (2) and clap's message naming the flag.
pub fn positive_f64(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        Ok(_) => Err(format!("expected a positive number, got {s}")),
        Err(_) => Err(format!("expected a positive number, got {s:?}")),
    }
}

/// A whole number of at least 1 (frame steps, frame counts, batch sizes).
pub fn positive_u64(s: &str) -> Result<u64, String> {
    match s.trim().parse::<u64>() {
        Ok(v) if v > 0 => Ok(v),
        _ => Err(format!("expected a whole number of at least 1, got {s:?}")),
    }
}

/// [`positive_u64`] as a `usize`.
pub fn positive_usize(s: &str) -> Result<usize, String> {
    positive_u64(s).and_then(|v| usize::try_from(v).map_err(|e| e.to_string()))
}

/// `--device`: a device name this build can run the network on (`cpu`, or `wgpu` in builds
/// with the `wgpu` feature), checked before the run so that a build without a GPU backend, or
/// an unknown name, is a wrong command line (exit 2) with the remedy.
pub fn device(s: &str) -> Result<String, String> {
    match vpcal_net::device::select(s) {
        Ok(_) => Ok(s.to_string()),
        Err(vpcal_net::NetError::Config(m)) => Err(m),
        Err(e) => Err(e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positive_values_refuse_zero_negative_and_non_numbers() {
        assert_eq!(positive_f64("2.5"), Ok(2.5));
        for bad in ["0", "-100", "nan", "inf", "x", ""] {
            assert!(positive_f64(bad).is_err(), "{bad}");
        }
        assert_eq!(positive_u64("3"), Ok(3));
        for bad in ["0", "-1", "1.5", "x"] {
            assert!(positive_u64(bad).is_err(), "{bad}");
        }
    }
}
