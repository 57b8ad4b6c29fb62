//! The one training-sample type shared by every data source (BoxCars116k, synthetic crops).

/// One vehicle crop with its geometric ground truth, before augmentation.
///
/// All coordinates are in **crop pixels**: x right, y down, origin at the crop's top-left
/// corner (pixel (0, 0) covers [0, 1) x [0, 1)). The crop may have any size; augmentation
/// produces the network's input size.
#[derive(Debug, Clone)]
pub struct Sample {
    /// Where the sample came from, used for the vehicle-level split and for error messages.
    pub id: SampleId,
    /// The crop (RGB, 8 bit).
    pub image: image::RgbImage,
    /// The 8 projected corners of the vehicle's 3D bounding box, crop pixels.
    ///
    /// Corner order (BoxCars116k's): 0-3 go round one horizontal face (front-left,
    /// front-right, rear-right, rear-left) and 4-7 are the corners of the other horizontal face
    /// in the same order (BoxCars puts the roof first, the synthetic renderer the floor; the
    /// edges are the same either way): see [`BB3D_EDGES_VP1`], [`BB3D_EDGES_VP2`],
    /// [`BB3D_EDGES_VERTICAL`].
    pub bb3d: [[f64; 2]; 8],
    /// First vanishing point (direction the vehicle faces), crop pixels. Finite.
    pub vp1: [f64; 2],
    /// Second vanishing point (parallel to the road, orthogonal to VP1), crop pixels. Finite.
    pub vp2: [f64; 2],
    /// How much the VP1 and VP2 labels are trusted, in [0, 1]: the weight of each VP's
    /// heatmaps in the loss. [`EXACT_LABELS`] for rendered or 3D-annotated vehicles; lower for
    /// self-labelled real footage, whose VPs come from an estimated camera (`vpcal label`).
    pub label_weight: [f32; 2],
}

/// The label weights of a sample whose VPs are exact (BoxCars116k, the renderer).
pub const EXACT_LABELS: [f32; 2] = [1.0, 1.0];

/// Corner pairs of [`Sample::bb3d`] whose edges run along the vehicle's length: their images
/// meet at VP1.
pub const BB3D_EDGES_VP1: [(usize, usize); 4] = [(0, 3), (1, 2), (4, 7), (5, 6)];
/// Corner pairs whose edges run across the vehicle: their images meet at VP2.
pub const BB3D_EDGES_VP2: [(usize, usize); 4] = [(0, 1), (3, 2), (4, 5), (7, 6)];
/// Corner pairs whose edges are vertical: their images meet at VP3.
pub const BB3D_EDGES_VERTICAL: [(usize, usize); 4] = [(0, 4), (1, 5), (2, 6), (3, 7)];

/// Identity of a sample: the vehicle and which of its instances (frames) this is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SampleId {
    /// Vehicle id; the split is `vehicle % 10` (0 validation, 1 test, else train).
    pub vehicle: u64,
    /// Instance index within the vehicle.
    pub instance: u32,
}

/// Dataset split, by vehicle id (DESIGN.md §6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Split {
    Train,
    Validation,
    Test,
}

impl Split {
    /// The split a vehicle belongs to: `vehicle % 10 == 0` validation, `== 1` test, else train.
    pub fn of_vehicle(vehicle: u64) -> Split {
        match vehicle % 10 {
            0 => Split::Validation,
            1 => Split::Test,
            _ => Split::Train,
        }
    }
}
