//! Parsers for flag values shared by the subcommands (`x,y` points, `x0,y0,x1,y1` boxes,
//! `WxH` sizes), with messages that say what was expected.

use vpcal_geom::Point2;

fn numbers<const N: usize>(s: &str, what: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!(
            "expected {what}, {N} comma-separated numbers, got {s:?}"
        ));
    }
    let mut out = [0.0; N];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("expected {what}, but {p:?} is not a finite number"))?;
    }
    Ok(out)
}

/// `x,y` in pixels.
pub fn point(s: &str) -> Result<Point2, String> {
    numbers::<2>(s, "a point x,y").map(Point2::from)
}

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

/// The principal point the BrnoCompSpeed files use for an image size: `(W/2 + 0.5, H/2 + 0.5)`.
pub fn bcs_principal_point(width: u32, height: u32) -> Point2 {
    Point2::new(f64::from(width) / 2.0 + 0.5, f64::from(height) / 2.0 + 0.5)
}
