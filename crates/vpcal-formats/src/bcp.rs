//! BrnoCarPark ground truth: `ground_truth/SXX/gt_pairs.json` = `[{"p1", "p2", "distance"}]`
//! with points in frame pixels (`[x, y]` or homogeneous `[x, y, w]`) and distances in metres.

use crate::error::FormatError;
use crate::fs::read_json;
use std::path::Path;
use vpcal_geom::metrics::RoadMeasurement;
use vpcal_geom::Point2;

/// Read `gt_pairs.json`.
///
/// # Errors
/// [`FormatError`] naming the file and the malformed pair.
pub fn read_gt_pairs(path: &Path) -> Result<Vec<RoadMeasurement>, FormatError> {
    let doc = read_json(path)?;
    let items = doc.as_array("$").map_err(|e| FormatError::field(path, e))?;
    let mut out = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let at = format!("[{i}]");
        let point = |key: &str| -> Result<Point2, FormatError> {
            let v = item
                .field(&at, key)
                .and_then(|v| v.as_f64_vec(&format!("{at}.{key}")))
                .map_err(|e| FormatError::field(path, e))?;
            match v.as_slice() {
                [x, y] => Ok(Point2::new(*x, *y)),
                [x, y, w] if *w != 0.0 => Ok(Point2::new(x / w, y / w)),
                _ => Err(FormatError::invalid(
                    path,
                    format!("{at}.{key}: expected [x, y] or [x, y, w]"),
                )),
            }
        };
        let distance_m = item
            .field(&at, "distance")
            .and_then(|v| v.as_f64(&format!("{at}.distance")))
            .map_err(|e| FormatError::field(path, e))?;
        if !(distance_m > 0.0 && distance_m.is_finite()) {
            return Err(FormatError::invalid(
                path,
                format!("{at}.distance: expected a positive distance, found {distance_m}"),
            ));
        }
        out.push(RoadMeasurement {
            p1: point("p1")?,
            p2: point("p2")?,
            distance_m,
        });
    }
    Ok(out)
}
