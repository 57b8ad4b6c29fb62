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
