//! Files of the reference implementation (deep_vp): per-vehicle VP outputs (`VPout_*.json`)
//! and object detections (`detections.json`).
//!
//! `VPout` files are lists with one item per detected box:
//! `{"box": [ymin, xmin, ymax, xmax] (normalised), "box_center": [cx, cy], "box_scale": [hw, hh],
//! "vp_box": [y_min, x_min, y_max, x_max] (integer pixels), "score", "frame_cnt",
//! "vp1_var", "vp2_var", "pred_vps": [[vp1x, vp1y, vp2x, vp2y] per scale] (box frame),
//! "pred_vars": [[D_vp1, D_vp2] per scale], "vp1_box", "vp2_box", "vp1", "vp2" (frame pixels)}`.
//! Numbers may be `Infinity` or `NaN` (the reference's files); vpcal writes them as `null`. Note that the reference's `vp2_var` is not VP2's spread
//! (it indexes VP1's column); [`VpOutItem::vp2_spread`] reads the right one from `pred_vars`.
//!
//! vpcal adds `"edgelets": [[x, y, angle, strength], ...]` (frame pixels, radians) to the items
//! it writes when it found edgelets in the box (`vpcal calibrate --vehicles`), so that
//! `vpcal aggregate` on that file sees what `calibrate` saw; other readers ignore the field.
//! It writes `"vps_copied": true` on the boxes the network did not see, whose `vp1`/`vp2` it
//! copied from an earlier box of the same vehicle (they count for tracks and edgelets, not as
//! rays); absent means false.
//!
//! `detections.json`: `[{"frame_cnt", "boxes": [[ymin, xmin, ymax, xmax] normalised], "scores"}]`.

use crate::error::FormatError;
use crate::fs::{read_json, write_json};
use crate::json::{AccessError, Json};
use std::path::Path;
use vpcal_geom::aggregate::edgelets::Edgelet;
use vpcal_geom::aggregate::verticals::Segment;
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
    /// vpcal's `vps_copied`: the VPs are an earlier box's of the same vehicle (module docs).
    pub vps_copied: bool,
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
        self.edgelets.iter().map(|&r| edgelet_from_row(r)).collect()
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
            copied: self.vps_copied,
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
            // A present null is a non-finite spread (strict JSON), not an absent one.
            vp1_var: item
                .get("vp1_var")
                .map(|v| v.as_f64(&path("vp1_var")))
                .transpose()?,
            vp2_var: item
                .get("vp2_var")
                .map(|v| v.as_f64(&path("vp2_var")))
                .transpose()?,
            edgelets,
            vps_copied: opt("vps_copied")
                .map(|v| v.as_bool(&path("vps_copied")))
                .transpose()?
                .unwrap_or(false),
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
        if self.vps_copied {
            put("vps_copied", Json::Bool(true));
        }
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
    vpout_from_json(&read_json(path)?, path)
}

/// The items of a `VPout` document already parsed (`path` names it in errors).
///
/// # Errors
/// As [`read_vpout`].
pub fn vpout_from_json(doc: &Json, path: &Path) -> Result<Vec<VpOutItem>, FormatError> {
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

/// Write a `VPout` file atomically, as strict JSON (non-finite numbers as `null`, read back as NaN).
///
/// # Errors
/// [`FormatError::Io`] naming the file.
pub fn write_vpout(path: &Path, items: &[VpOutItem]) -> Result<(), FormatError> {
    write_json(
        path,
        &Json::Array(items.iter().map(VpOutItem::to_json).collect()),
    )
}

/// An edgelet as vpcal's files write it: `[x, y, angle, strength]` (frame pixels, radians).
pub fn edgelet_row(e: &Edgelet) -> [f64; 4] {
    [e.x, e.y, e.angle, e.strength]
}

/// The edgelet of a row [`edgelet_row`] wrote.
pub fn edgelet_from_row([x, y, angle, strength]: [f64; 4]) -> Edgelet {
    Edgelet {
        x,
        y,
        angle,
        strength,
    }
}

/// Format tag of the scene file that `vpcal calibrate --scene-edgelets` writes beside the
/// per-vehicle records: what the scene's background shows, its edgelets (which move VP1 to
/// where the lines along the road meet) and its line segments (whose vertical ones measure
/// the focal length), so that `vpcal aggregate --scene-edgelets` finds the same camera.
pub const SCENE_EDGELETS_FORMAT: &str = "vpcal-scene-edgelets/2";

/// The earlier format: edgelets only (read as a scene without segments).
pub const SCENE_EDGELETS_FORMAT_V1: &str = "vpcal-scene-edgelets/1";

/// What a scene file holds (frame pixels).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SceneRecord {
    pub edgelets: Vec<Edgelet>,
    pub segments: Vec<Segment>,
}

/// Write the scene's edgelets and segments (`{"format", "edgelets": [[x, y, angle,
/// strength], ...], "segments": [[x0, y0, x1, y1], ...]}`, frame pixels and radians)
/// atomically.
///
/// # Errors
/// [`FormatError::Io`] naming the file.
pub fn write_scene_edgelets(path: &Path, scene: &SceneRecord) -> Result<(), FormatError> {
    let edgelets = scene
        .edgelets
        .iter()
        .map(|e| Json::from(&edgelet_row(e)[..]))
        .collect();
    let segments = scene
        .segments
        .iter()
        .map(|s| Json::from(&[s.a.x, s.a.y, s.b.x, s.b.y][..]))
        .collect();
    write_json(
        path,
        &Json::Object(vec![
            ("format".into(), Json::String(SCENE_EDGELETS_FORMAT.into())),
            ("edgelets".into(), Json::Array(edgelets)),
            ("segments".into(), Json::Array(segments)),
        ]),
    )
}

/// Read a file [`write_scene_edgelets`] wrote (or one of the earlier format, without
/// segments).
///
/// # Errors
/// [`FormatError`] naming the file and, for a malformed one, the field.
pub fn read_scene_edgelets(path: &Path) -> Result<SceneRecord, FormatError> {
    let doc = read_json(path)?;
    let format = doc
        .field("$", "format")
        .and_then(|f| f.as_str("$.format"))
        .map_err(|e| FormatError::field(path, e))?;
    if format != SCENE_EDGELETS_FORMAT && format != SCENE_EDGELETS_FORMAT_V1 {
        return Err(FormatError::invalid(
            path,
            format!("format `{format}`: expected `{SCENE_EDGELETS_FORMAT}`"),
        ));
    }
    let rows = |key: &str| {
        doc.field("$", key)
            .and_then(|r| r.as_array(&format!("$.{key}")))
            .map_err(|e| FormatError::field(path, e))
    };
    let edgelets = rows("edgelets")?
        .iter()
        .enumerate()
        .map(|(i, r)| {
            r.as_f64_array::<4>(&format!("$.edgelets[{i}]"))
                .map(edgelet_from_row)
                .map_err(|e| FormatError::field(path, e))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let segments = if format == SCENE_EDGELETS_FORMAT_V1 {
        Vec::new()
    } else {
        rows("segments")?
            .iter()
            .enumerate()
            .map(|(i, r)| {
                r.as_f64_array::<4>(&format!("$.segments[{i}]"))
                    .map(|[x0, y0, x1, y1]| Segment {
                        a: Point2::new(x0, y0),
                        b: Point2::new(x1, y1),
                    })
                    .map_err(|e| FormatError::field(path, e))
            })
            .collect::<Result<Vec<_>, _>>()?
    };
    Ok(SceneRecord { edgelets, segments })
}

/// The frame size `(width, height)` the items' boxes were measured in, from each box in
/// both forms (normalised `box` and pixel `vp_box`): the reference truncates
/// (`x_min = int(W·xmin)`, `x_max = int(W·xmax + 1)`), vpcal writes exact quotients; each box
/// bounds `W` and `H` to an interval, and the size is the one integer in all of them.
///
/// # Errors
/// A message when the items have no boxes in both forms, or their bounds leave no integer or
/// several.
pub fn infer_image_size(items: &[VpOutItem]) -> Result<(u32, u32), String> {
    // Bounds [lo, hi] on W (index 0) and H (index 1).
    let mut bounds = [[0.0f64, f64::INFINITY]; 2];
    let mut used = 0usize;
    for item in items {
        let (Some(n), Some(px)) = (item.box_norm, item.vp_box) else {
            continue;
        };
        // n and px are [y0, x0, y1, x1]; axis 0 is x (W), 1 is y (H).
        for (axis, (lo_i, hi_i)) in [(0usize, (1usize, 3usize)), (1, (0, 2))] {
            let b = &mut bounds[axis];
            if n[lo_i] > 0.01 {
                b[0] = b[0].max(px[lo_i] / n[lo_i]);
                b[1] = b[1].min((px[lo_i] + 1.0) / n[lo_i]);
            }
            if n[hi_i] > 0.01 {
                b[0] = b[0].max((px[hi_i] - 1.0) / n[hi_i]);
                b[1] = b[1].min(px[hi_i] / n[hi_i]);
            }
        }
        used += 1;
    }
    if used == 0 {
        return Err("no item has its box both normalised (`box`) and in pixels (`vp_box`)".into());
    }
    let mut size = [0u32; 2];
    for (axis, name) in [(0, "width"), (1, "height")] {
        let [lo, hi] = bounds[axis];
        // Rounding in the files: a relative margin of 1e-9.
        let first = (lo * (1.0 - 1e-9)).ceil();
        let last = (hi * (1.0 + 1e-9)).floor();
        if !(first.is_finite() && last.is_finite()) || first > last {
            return Err(format!(
                "the boxes of {used} items agree on no frame {name} (bounds {lo:.2}-{hi:.2} px)"
            ));
        }
        if first < last {
            return Err(format!(
                "the boxes of {used} items leave the frame {name} between {first} and {last} px"
            ));
        }
        size[axis] = first as u32;
    }
    Ok((size[0], size[1]))
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

    /// This frame's boxes scored at least `min_score`, as [`ReferenceDetections::box_px`]
    /// gives them in a `width` x `height` frame.
    pub fn boxes_px(
        &self,
        min_score: f64,
        width: u32,
        height: u32,
    ) -> impl Iterator<Item = BoxPx> + '_ {
        self.boxes
            .iter()
            .zip(&self.scores)
            .filter(move |(_, s)| **s >= min_score)
            .map(move |(b, _)| Self::box_px(*b, width, height))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_edgelets_survive_the_file_and_a_wrong_file_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.json");
        let e = vec![
            Edgelet {
                x: 1.25,
                y: 2.5,
                angle: -0.125,
                strength: 30.0,
            },
            Edgelet {
                x: 640.0,
                y: 0.5,
                angle: 3.0,
                strength: 8.5,
            },
        ];
        let scene = SceneRecord {
            edgelets: e.clone(),
            segments: vec![Segment {
                a: Point2::new(10.0, 20.5),
                b: Point2::new(12.25, 90.0),
            }],
        };
        write_scene_edgelets(&path, &scene).unwrap();
        assert_eq!(read_scene_edgelets(&path).unwrap(), scene);
        write_scene_edgelets(&path, &SceneRecord::default()).unwrap();
        assert_eq!(read_scene_edgelets(&path).unwrap(), SceneRecord::default());
        // The earlier format: edgelets only.
        std::fs::write(
            &path,
            r#"{"format": "vpcal-scene-edgelets/1", "edgelets": [[1.25, 2.5, -0.125, 30]]}"#,
        )
        .unwrap();
        assert_eq!(read_scene_edgelets(&path).unwrap().edgelets, e[..1]);
        std::fs::write(&path, r#"{"format": "vpcal-tracks/1", "edgelets": []}"#).unwrap();
        let err = read_scene_edgelets(&path).unwrap_err().to_string();
        assert!(
            err.contains("scene.json") && err.contains("vpcal-scene-edgelets/2"),
            "{err}"
        );
        std::fs::write(
            &path,
            r#"{"format": "vpcal-scene-edgelets/1", "edgelets": [[1, 2, 3]]}"#,
        )
        .unwrap();
        let err = read_scene_edgelets(&path).unwrap_err().to_string();
        assert!(err.contains("edgelets[0]"), "{err}");
        std::fs::write(
            &path,
            r#"{"format": "vpcal-scene-edgelets/2", "edgelets": [], "segments": [[1, 2, 3]]}"#,
        )
        .unwrap();
        let err = read_scene_edgelets(&path).unwrap_err().to_string();
        assert!(err.contains("segments[0]"), "{err}");
    }

    fn item(box_norm: [f64; 4], vp_box: [f64; 4]) -> VpOutItem {
        VpOutItem {
            frame_cnt: 0.0,
            score: 0.9,
            vp1: Point2::new(0.0, 0.0),
            vp2: Point2::new(1.0, 0.0),
            box_norm: Some(box_norm),
            box_center: None,
            box_scale: None,
            vp_box: Some(vp_box),
            vp1_box: None,
            vp2_box: None,
            pred_vps: Vec::new(),
            pred_vars: Vec::new(),
            vp1_var: None,
            vp2_var: None,
            edgelets: Vec::new(),
            vps_copied: false,
        }
    }

    #[test]
    fn the_image_size_follows_from_boxes_in_both_conventions() {
        let (w, h) = (320.0f64, 240.0f64);
        // vpcal's exact quotients.
        let ours: Vec<VpOutItem> = [[12.0, 30.0, 80.0, 95.0], [100.0, 150.0, 160.0, 239.0]]
            .iter()
            .map(|b| item([b[0] / h, b[1] / w, b[2] / h, b[3] / w], *b))
            .collect();
        assert_eq!(infer_image_size(&ours), Ok((320, 240)));
        // The reference's truncation, from normalised boxes of a 1920x1080 frame.
        let (w, h) = (1920.0f64, 1080.0f64);
        let reference: Vec<VpOutItem> = [
            [0.3012, 0.4121, 0.4577, 0.5333],
            [0.1234, 0.0567, 0.2401, 0.1999],
            [0.6001, 0.7003, 0.8888, 0.9111],
        ]
        .iter()
        .map(|n| {
            let px = [
                (h * n[0]).floor(),
                (w * n[1]).floor(),
                (h * n[2] + 1.0).floor(),
                (w * n[3] + 1.0).floor(),
            ];
            item(*n, px)
        })
        .collect();
        assert_eq!(infer_image_size(&reference), Ok((1920, 1080)));
        // One small box leaves several sizes; none at all, an error.
        let e = infer_image_size(
            &reference[..1]
                .iter()
                .map(|i| VpOutItem {
                    box_norm: Some([0.3, 0.4, 0.45, 0.5]),
                    vp_box: Some([3.0, 4.0, 5.0, 5.0]),
                    ..i.clone()
                })
                .collect::<Vec<_>>(),
        )
        .unwrap_err();
        assert!(e.contains("between"), "{e}");
        let bare = VpOutItem {
            box_norm: None,
            ..ours[0].clone()
        };
        assert!(infer_image_size(&[bare]).unwrap_err().contains("no item"));
    }
}
