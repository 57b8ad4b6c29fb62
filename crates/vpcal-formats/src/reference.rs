//! Files of the reference implementation (deep_vp): per-vehicle VP outputs (`VPout_*.json`)
//! and object detections (`detections.json`).
//!
//! `VPout` files are lists with one item per detected box:
//! `{"box": [ymin, xmin, ymax, xmax] (normalised), "box_center": [cx, cy], "box_scale": [hw, hh],
//! "vp_box": [y_min, x_min, y_max, x_max] (integer pixels), "score", "frame_cnt",
//! "vp1_var", "vp2_var", "pred_vps": [[vp1x, vp1y, vp2x, vp2y] per scale] (box frame),
//! "pred_vars": [[D_vp1, D_vp2] per scale], "vp1_box", "vp2_box", "vp1", "vp2" (frame pixels)}`.
//! Numbers may be `Infinity` or `NaN`. Note that the reference's `vp2_var` is not VP2's spread
//! (it indexes VP1's column); [`VpOutItem::vp2_spread`] reads the right one from `pred_vars`.
//!
//! vpcal adds `"edgelets": [[x, y, angle, strength], ...]` (frame pixels, radians) to the items
//! it writes when it found edgelets in the box (`vpcal calibrate --vehicles`), so that
//! `vpcal aggregate` on that file sees what `calibrate` saw; other readers ignore the field.
//!
//! `detections.json`: `[{"frame_cnt", "boxes": [[ymin, xmin, ymax, xmax] normalised], "scores"}]`.

use crate::error::FormatError;
use crate::fs::{read_json, write_json};
use crate::json::{AccessError, Json};
use std::path::Path;
use vpcal_geom::aggregate::edgelets::Edgelet;
use vpcal_geom::aggregate::VehicleVps;
use vpcal_geom::{BoxPx, Point2};

/// One item of a `VPout` file. Optional fields are `None` when absent.
#[derive(Debug, Clone, PartialEq)]
pub struct VpOutItem {
    /// The reference's frame counter (`frame_cnt`).
    pub frame_cnt: f64,
    /// Detector score.
    pub score: f64,
    /// VP1, frame pixels (may be non-finite).
    pub vp1: Point2,
    /// VP2, frame pixels (may be non-finite).
    pub vp2: Point2,
    /// Normalised box `[ymin, xmin, ymax, xmax]` as the detector gave it.
    pub box_norm: Option<[f64; 4]>,
    /// Box centre, frame pixels.
    pub box_center: Option<Point2>,
    /// Box half sizes (hw, hh), frame pixels.
    pub box_scale: Option<Point2>,
    /// Integer crop box `[y_min, x_min, y_max, x_max]` (end exclusive).
    pub vp_box: Option<[f64; 4]>,
    /// VP1 in the box frame.
    pub vp1_box: Option<Point2>,
    /// VP2 in the box frame.
    pub vp2_box: Option<Point2>,
    /// Decoded VPs per scale, `[vp1x, vp1y, vp2x, vp2y]`, box frame.
    pub pred_vps: Vec<[f64; 4]>,
    /// Spreads `D^s` per scale, `[vp1, vp2]`.
    pub pred_vars: Vec<[f64; 2]>,
    /// The reference's `vp1_var`.
    pub vp1_var: Option<f64>,
    /// The reference's `vp2_var` (see the module docs).
    pub vp2_var: Option<f64>,
    /// vpcal's edgelets in the box, `[x, y, angle, strength]` (empty when absent).
    pub edgelets: Vec<[f64; 4]>,
}

impl VpOutItem {
    /// The vehicle box in frame pixels (from `box_center` and `box_scale`).
    pub fn box_px(&self) -> Option<BoxPx> {
        let (c, s) = (self.box_center?, self.box_scale?);
        Some(BoxPx::new(c.x - s.x, c.y - s.y, c.x + s.x, c.y + s.y))
    }

    /// The smallest spread of one column of `pred_vars` (NaN counts as `+inf`): the spread of
    /// the scale the decoder selected.
    fn selected_spread(&self, column: usize) -> Option<f64> {
        self.pred_vars
            .iter()
            .map(|v| {
                if v[column].is_nan() {
                    f64::INFINITY
                } else {
                    v[column]
                }
            })
            .reduce(f64::min)
    }

    /// The spread of the scale selected for VP1 (the smallest in `pred_vars`' first column).
    pub fn vp1_spread(&self) -> Option<f64> {
        self.selected_spread(0)
    }

    /// The spread of the scale selected for VP2 (the smallest in `pred_vars`' second column).
    pub fn vp2_spread(&self) -> Option<f64> {
        self.selected_spread(1)
    }

    /// The item's edgelets.
    pub fn edgelets(&self) -> Vec<Edgelet> {
        self.edgelets
            .iter()
            .map(|&[x, y, angle, strength]| Edgelet {
                x,
                y,
                angle,
                strength,
            })
            .collect()
    }

    /// The item as aggregation evidence.
    pub fn to_vehicle(&self) -> VehicleVps {
        VehicleVps {
            vp1: self.vp1,
            vp2: self.vp2,
            score: self.score,
            box_px: self.box_px(),
            frame: Some(self.frame_cnt),
            vp1_spread: self.vp1_spread(),
            vp2_spread: self.vp2_spread(),
        }
    }

    fn from_json(item: &Json, at: &str) -> Result<VpOutItem, AccessError> {
        let opt = |key: &str| item.get(key).filter(|v| **v != Json::Null);
        let path = |key: &str| format!("{at}.{key}");
        let point = |key: &str| -> Result<Option<Point2>, AccessError> {
            opt(key).map(|v| v.as_point(&path(key))).transpose()
        };
        let rows = |key: &str| -> Result<Vec<Json>, AccessError> {
            Ok(opt(key)
                .map(|v| v.as_array(&path(key)).map(<[Json]>::to_vec))
                .transpose()?
                .unwrap_or_default())
        };
        let pred_vps = rows("pred_vps")?
            .iter()
            .enumerate()
            .map(|(i, r)| r.as_f64_array::<4>(&format!("{}[{i}]", path("pred_vps"))))
            .collect::<Result<_, _>>()?;
        let edgelets = rows("edgelets")?
            .iter()
            .enumerate()
            .map(|(i, r)| r.as_f64_array::<4>(&format!("{}[{i}]", path("edgelets"))))
            .collect::<Result<_, _>>()?;
        let pred_vars = rows("pred_vars")?
            .iter()
            .enumerate()
            .map(|(i, r)| r.as_f64_array::<2>(&format!("{}[{i}]", path("pred_vars"))))
            .collect::<Result<_, _>>()?;
        Ok(VpOutItem {
            frame_cnt: item.field(at, "frame_cnt")?.as_f64(&path("frame_cnt"))?,
            score: item.field(at, "score")?.as_f64(&path("score"))?,
            vp1: item.field(at, "vp1")?.as_point(&path("vp1"))?,
            vp2: item.field(at, "vp2")?.as_point(&path("vp2"))?,
            box_norm: opt("box")
                .map(|v| v.as_f64_array::<4>(&path("box")))
                .transpose()?,
            box_center: point("box_center")?,
            box_scale: point("box_scale")?,
            vp_box: opt("vp_box")
                .map(|v| v.as_f64_array::<4>(&path("vp_box")))
                .transpose()?,
            vp1_box: point("vp1_box")?,
            vp2_box: point("vp2_box")?,
            pred_vps,
            pred_vars,
            vp1_var: opt("vp1_var")
                .map(|v| v.as_f64(&path("vp1_var")))
                .transpose()?,
            vp2_var: opt("vp2_var")
                .map(|v| v.as_f64(&path("vp2_var")))
                .transpose()?,
            edgelets,
        })
    }

    /// The item as JSON, with the reference's field names and order.
    pub fn to_json(&self) -> Json {
        let mut m: Vec<(String, Json)> = Vec::new();
        let mut put = |k: &str, v: Json| m.push((k.to_string(), v));
        if let Some(b) = self.box_norm {
            put("box", Json::from(&b[..]));
        }
        if let Some(c) = self.box_center {
            put("box_center", c.into());
        }
        if let Some(s) = self.box_scale {
            put("box_scale", s.into());
        }
        if let Some(b) = self.vp_box {
            put("vp_box", Json::from(&b[..]));
        }
        put("score", self.score.into());
        put("frame_cnt", self.frame_cnt.into());
        if let Some(v) = self.vp1_var {
            put("vp1_var", v.into());
        }
        if let Some(v) = self.vp2_var {
            put("vp2_var", v.into());
        }
        if !self.pred_vps.is_empty() {
            put(
                "pred_vps",
                Json::Array(self.pred_vps.iter().map(|r| Json::from(&r[..])).collect()),
            );
        }
        if !self.pred_vars.is_empty() {
            put(
                "pred_vars",
                Json::Array(self.pred_vars.iter().map(|r| Json::from(&r[..])).collect()),
            );
        }
        if let Some(v) = self.vp1_box {
            put("vp1_box", v.into());
        }
        if let Some(v) = self.vp2_box {
            put("vp2_box", v.into());
        }
        put("vp1", self.vp1.into());
        put("vp2", self.vp2.into());
        if !self.edgelets.is_empty() {
            put(
                "edgelets",
                Json::Array(self.edgelets.iter().map(|r| Json::from(&r[..])).collect()),
            );
        }
        Json::Object(m)
    }
}

/// Read a `VPout_*.json` file.
///
/// # Errors
/// [`FormatError`] naming the file and, for a malformed item, its index and field.
pub fn read_vpout(path: &Path) -> Result<Vec<VpOutItem>, FormatError> {
    let doc = read_json(path)?;
    let items = doc.as_array("$").map_err(|e| FormatError::field(path, e))?;
    items
        .iter()
        .enumerate()
        .map(|(i, item)| {
            VpOutItem::from_json(item, &format!("item [{i}]"))
                .map_err(|e| FormatError::field(path, e))
        })
        .collect()
}

/// Write a `VPout` file atomically (non-finite numbers as `Infinity`/`NaN`, as Python does).
///
/// # Errors
/// [`FormatError::Io`] naming the file.
pub fn write_vpout(path: &Path, items: &[VpOutItem]) -> Result<(), FormatError> {
    write_json(
        path,
        &Json::Array(items.iter().map(VpOutItem::to_json).collect()),
    )
}

/// One frame of the reference's `detections.json`.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceDetections {
    /// The reference's frame counter.
    pub frame_cnt: f64,
    /// Boxes `[ymin, xmin, ymax, xmax]`, normalised to [0, 1].
    pub boxes: Vec<[f64; 4]>,
    /// Detector scores, one per box.
    pub scores: Vec<f64>,
}

impl ReferenceDetections {
    /// The reference's integer pixel box of normalised box `b` in a `width` x `height` frame:
    /// `x_min = int(W·xmin)`, `x_max = int(W·xmax + 1)` (likewise y; `int` truncates), as a
    /// [`BoxPx`] whose centre and half sizes are those the reference used for the box frame.
    pub fn box_px(b: [f64; 4], width: u32, height: u32) -> BoxPx {
        let (w, h) = (f64::from(width), f64::from(height));
        BoxPx::new(
            (w * b[1]).trunc(),
            (h * b[0]).trunc(),
            (w * b[3] + 1.0).trunc(),
            (h * b[2] + 1.0).trunc(),
        )
    }
}

/// Read the reference's `detections.json`.
///
/// # Errors
/// [`FormatError`] naming the file and the malformed frame; also when a frame has a different
/// number of boxes and scores.
pub fn read_detections(path: &Path) -> Result<Vec<ReferenceDetections>, FormatError> {
    let doc = read_json(path)?;
    let frames = doc.as_array("$").map_err(|e| FormatError::field(path, e))?;
    let mut out = Vec::with_capacity(frames.len());
    for (i, f) in frames.iter().enumerate() {
        let at = format!("frame [{i}]");
        let parse = || -> Result<ReferenceDetections, AccessError> {
            let boxes = f
                .field(&at, "boxes")?
                .as_array(&format!("{at}.boxes"))?
                .iter()
                .enumerate()
                .map(|(k, b)| b.as_f64_array::<4>(&format!("{at}.boxes[{k}]")))
                .collect::<Result<Vec<_>, _>>()?;
            let scores = f
                .field(&at, "scores")?
                .as_f64_vec(&format!("{at}.scores"))?;
            Ok(ReferenceDetections {
                frame_cnt: f
                    .field(&at, "frame_cnt")?
                    .as_f64(&format!("{at}.frame_cnt"))?,
                boxes,
                scores,
            })
        };
        let d = parse().map_err(|e| FormatError::field(path, e))?;
        if d.boxes.len() != d.scores.len() {
            return Err(FormatError::invalid(
                path,
                format!(
                    "{at}: {} boxes but {} scores",
                    d.boxes.len(),
                    d.scores.len()
                ),
            ));
        }
        out.push(d);
    }
    Ok(out)
}
