//! Weights as safetensors files, with the model config in the file's metadata.
//!
//! Tensor names are the module paths (`front.conv.weight`, `stacks.0.head_bn.running_mean`),
//! f32, little-endian, shapes as in burn (`[out, in, kh, kw]` for convolutions). Metadata keys:
//! - `vpcal.format`: [`WEIGHTS_FORMAT`];
//! - `vpcal.kind`: the architecture ([`VpNetwork::KIND`](crate::network::VpNetwork::KIND));
//! - `vpcal.config`: the model config (e.g. [`ModelConfig`](crate::ModelConfig)) as JSON;
//! - `vpcal.param_ids`: JSON object tensor name -> burn parameter id (decimal string), so that
//!   optimizer state saved beside the weights (keyed by id) applies again after loading
//!   (batch-norm running statistics are buffers and keep fresh ids).
//!
//! Loading refuses a file whose tensors do not match the model exactly: a missing or unexpected
//! tensor, or a shape mismatch naming the tensor and both shapes.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param, ParamId};
use burn::tensor::{DType, Tensor, TensorData};
use safetensors::tensor::{Dtype, TensorView};

use crate::NetError;

/// Value of the `vpcal.format` metadata key written by this version.
pub const WEIGHTS_FORMAT: &str = "vpcal-net-weights/1";

const KEY_FORMAT: &str = "vpcal.format";
const KEY_CONFIG: &str = "vpcal.config";
const KEY_KIND: &str = "vpcal.kind";
const KEY_IDS: &str = "vpcal.param_ids";

/// One parameter (or running statistic) read out of a module.
#[derive(Debug, Clone)]
pub struct NamedTensor {
    pub name: String,
    pub id: ParamId,
    pub shape: Vec<usize>,
    pub values: Vec<f32>,
}

/// The path of the module a visitor or mapper is in. An enum's variant adds no name to it (an
/// enum of backbones stores each as the backbone itself).
#[derive(Default)]
struct ModulePath(Vec<String>);

impl ModulePath {
    fn enter(&mut self, name: &str, container_type: &str) {
        if !container_type.starts_with("Enum:") {
            self.0.push(name.to_string());
        }
    }
    fn exit(&mut self, container_type: &str) {
        if !container_type.starts_with("Enum:") {
            self.0.pop();
        }
    }
    /// The dotted tensor name (`stacks.0.head_bn.running_mean`).
    fn name(&self) -> String {
        self.0.join(".")
    }
}

#[derive(Default)]
struct Collector {
    path: ModulePath,
    out: Vec<NamedTensor>,
    error: Option<String>,
}

impl ModuleVisitor for Collector {
    fn enter_module(&mut self, name: &str, container_type: &str) {
        self.path.enter(name, container_type);
    }
    fn exit_module(&mut self, _name: &str, container_type: &str) {
        self.path.exit(container_type);
    }
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let name = self.path.name();
        let data = param.val().into_data();
        let shape = data.shape().to_vec();
        match data.convert::<f32>().try_to_vec::<f32>() {
            Ok(values) => self.out.push(NamedTensor {
                name,
                id: param.id,
                shape,
                values,
            }),
            Err(e) => {
                self.error.get_or_insert(format!("tensor {name}: {e:?}"));
            }
        }
    }
}

/// All float tensors of a module with their paths, in traversal order.
///
/// # Errors
/// [`NetError::Tensor`] when a tensor cannot be read as f32.
pub fn named_tensors<M: Module>(module: &M) -> Result<Vec<NamedTensor>, NetError> {
    let mut c = Collector::default();
    module.visit(&mut c);
    match c.error {
        Some(e) => Err(NetError::Tensor(e)),
        None => Ok(c.out),
    }
}

/// Serialise a module's tensors and config to safetensors bytes.
///
/// # Errors
/// [`NetError::Tensor`] when a tensor cannot be read, [`NetError::Format`] from the encoder.
pub fn weights_to_bytes<M: Module, C: serde::Serialize>(
    module: &M,
    config: &C,
    kind: &str,
) -> Result<Vec<u8>, NetError> {
    let tensors = named_tensors(module)?;
    let bytes: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
        .iter()
        .map(|t| {
            let mut b = Vec::with_capacity(t.values.len() * 4);
            for v in &t.values {
                b.extend_from_slice(&v.to_le_bytes());
            }
            (t.name.clone(), t.shape.clone(), b)
        })
        .collect();
    let mut views = Vec::with_capacity(bytes.len());
    for (name, shape, b) in &bytes {
        let view = TensorView::new(Dtype::F32, shape.clone(), b)
            .map_err(|e| NetError::Format(format!("tensor {name}: {e}")))?;
        views.push((name.as_str(), view));
    }
    let ids: BTreeMap<&str, String> = tensors
        .iter()
        .map(|t| (t.name.as_str(), t.id.val().to_string()))
        .collect();
    let mut meta = HashMap::new();
    meta.insert(KEY_FORMAT.to_string(), WEIGHTS_FORMAT.to_string());
    meta.insert(KEY_KIND.to_string(), kind.to_string());
    meta.insert(KEY_CONFIG.to_string(), serde_json::to_string(config)?);
    meta.insert(KEY_IDS.to_string(), serde_json::to_string(&ids)?);
    safetensors::serialize(views, Some(meta)).map_err(|e| NetError::Format(e.to_string()))
}

/// Write a module's weights to `path` atomically (temp file in the same folder, then rename).
///
/// # Errors
/// [`NetError::Io`] naming the file, or the errors of [`weights_to_bytes`].
pub fn save_weights<M: Module, C: serde::Serialize>(
    module: &M,
    config: &C,
    kind: &str,
    path: &Path,
) -> Result<(), NetError> {
    let bytes = weights_to_bytes(module, config, kind)?;
    crate::fsutil::write_atomic(path, &bytes)
}

/// A parsed weights file: tensors by name plus the metadata.
#[derive(Debug)]
pub struct WeightsFile {
    /// The architecture stored with the weights (`None` for a foreign safetensors file).
    pub kind: Option<String>,
    /// The model config JSON stored with the weights (`None` for a foreign file).
    config_json: Option<String>,
    tensors: HashMap<String, (Vec<usize>, Vec<f32>)>,
    ids: HashMap<String, u64>,
    path: std::path::PathBuf,
}

impl WeightsFile {
    /// Read and parse a safetensors file.
    ///
    /// # Errors
    /// [`NetError::Io`] when unreadable, [`NetError::Weights`] when it is not a safetensors
    /// file of f32 tensors or its metadata is malformed; both name the file.
    pub fn read(path: &Path) -> Result<WeightsFile, NetError> {
        let bytes = std::fs::read(path).map_err(|e| NetError::io(path, e))?;
        Self::parse(&bytes, path)
    }

    /// Parse safetensors bytes (`path` is used in error messages).
    ///
    /// # Errors
    /// As [`WeightsFile::read`].
    pub fn parse(bytes: &[u8], path: &Path) -> Result<WeightsFile, NetError> {
        let bad = |message: String| NetError::Weights {
            path: path.to_path_buf(),
            message,
        };
        let st = safetensors::SafeTensors::deserialize(bytes)
            .map_err(|e| bad(format!("not a safetensors file: {e}")))?;
        let (_, meta) = safetensors::SafeTensors::read_metadata(bytes)
            .map_err(|e| bad(format!("not a safetensors file: {e}")))?;
        let meta = meta.metadata().clone().unwrap_or_default();
        let config_json = meta.get(KEY_CONFIG).cloned();
        let kind = meta.get(KEY_KIND).cloned();
        if let Some(fmt) = meta.get(KEY_FORMAT) {
            if fmt != WEIGHTS_FORMAT {
                return Err(bad(format!(
                    "weights format {fmt:?}, this build reads {WEIGHTS_FORMAT:?}"
                )));
            }
        }
        let mut ids = HashMap::new();
        if let Some(text) = meta.get(KEY_IDS) {
            let map: BTreeMap<String, String> = serde_json::from_str(text)
                .map_err(|e| bad(format!("metadata {KEY_IDS} is malformed: {e}")))?;
            for (name, id) in map {
                let id = id
                    .parse::<u64>()
                    .map_err(|_| bad(format!("metadata {KEY_IDS}: id {id:?} of {name}")))?;
                ids.insert(name, id);
            }
        }
        let mut tensors = HashMap::new();
        for (name, view) in st.tensors() {
            if view.dtype() != Dtype::F32 {
                return Err(bad(format!(
                    "tensor {name} has dtype {:?}, expected F32",
                    view.dtype()
                )));
            }
            let values: Vec<f32> = view
                .data()
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            tensors.insert(name, (view.shape().to_vec(), values));
        }
        Ok(WeightsFile {
            kind,
            config_json,
            tensors,
            ids,
            path: path.to_path_buf(),
        })
    }

    /// The model config stored in the metadata, parsed as `C`; `None` when absent.
    ///
    /// # Errors
    /// [`NetError::Weights`] when present but not a `C`.
    pub fn config<C: serde::de::DeserializeOwned>(&self) -> Result<Option<C>, NetError> {
        match &self.config_json {
            None => Ok(None),
            Some(text) => serde_json::from_str(text)
                .map(Some)
                .map_err(|e| NetError::Weights {
                    path: self.path.clone(),
                    message: format!("metadata {KEY_CONFIG} is not the expected model config: {e}"),
                }),
        }
    }

    /// The path the file was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Names of the tensors in the file, sorted.
    pub fn names(&self) -> Vec<&str> {
        let mut v: Vec<&str> = self.tensors.keys().map(String::as_str).collect();
        v.sort_unstable();
        v
    }

    /// Load the file's tensors into `module`, which must have exactly the same tensors and
    /// shapes. Parameter ids are restored from the metadata when present.
    ///
    /// # Errors
    /// [`NetError::Weights`] naming the file and listing every mismatch: a tensor the model
    /// expects but the file lacks, a tensor the model does not have, or a shape mismatch
    /// (`tensor NAME: file has [..], model expects [..]`).
    pub fn load_into<M: Module>(&self, module: M) -> Result<M, NetError> {
        let mut mapper = Loader {
            file: self,
            path: ModulePath::default(),
            used: Vec::new(),
            problems: Vec::new(),
        };
        let module = module.map(&mut mapper);
        let mut problems = mapper.problems;
        let mut unused: Vec<&str> = self
            .tensors
            .keys()
            .map(String::as_str)
            .filter(|n| !mapper.used.iter().any(|u| u == n))
            .collect();
        unused.sort_unstable();
        for name in unused {
            problems.push(format!("tensor {name} is in the file but not in the model"));
        }
        if problems.is_empty() {
            Ok(module)
        } else {
            Err(NetError::Weights {
                path: self.path.clone(),
                message: format!(
                    "weights do not match the model ({} problem(s)): {}",
                    problems.len(),
                    problems.join("; ")
                ),
            })
        }
    }
}

struct Loader<'a> {
    file: &'a WeightsFile,
    path: ModulePath,
    used: Vec<String>,
    problems: Vec<String>,
}

impl ModuleMapper for Loader<'_> {
    fn enter_module(&mut self, name: &str, container_type: &str) {
        self.path.enter(name, container_type);
    }
    fn exit_module(&mut self, _name: &str, container_type: &str) {
        self.path.exit(container_type);
    }
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let name = self.path.name();
        let expected = param.lazy_shape().to_vec();
        let Some((shape, values)) = self.file.tensors.get(&name) else {
            self.problems.push(format!(
                "tensor {name} {expected:?} is missing from the file"
            ));
            return param;
        };
        self.used.push(name.clone());
        if *shape != expected {
            self.problems.push(format!(
                "tensor {name}: file has shape {shape:?}, model expects {expected:?}"
            ));
            return param;
        }
        let device = param.lazy_device();
        let data = TensorData::new(values.clone(), shape.clone());
        let tensor = Tensor::<D>::from_data(data, (&device, DType::F32));
        let id = self
            .file
            .ids
            .get(&name)
            .map_or(param.id, |&id| ParamId::from(id));
        param.transform_for_load(tensor, id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ModelConfig, StackedHourglass};
    use burn::tensor::Device;

    #[test]
    fn round_trip_is_bit_identical_and_keeps_ids() {
        let config = ModelConfig::tiny();
        let device = Device::flex();
        device.seed(7);
        let a = StackedHourglass::new(&config, &device);
        let bytes = weights_to_bytes(&a, &config, "stacked_hourglass").unwrap();
        let file = WeightsFile::parse(&bytes, Path::new("mem.safetensors")).unwrap();
        assert_eq!(file.config::<ModelConfig>().unwrap(), Some(config.clone()));
        assert_eq!(file.kind.as_deref(), Some("stacked_hourglass"));
        device.seed(8);
        let b = file
            .load_into(StackedHourglass::new(&config, &device))
            .unwrap();
        let ta = named_tensors(&a).unwrap();
        let tb = named_tensors(&b).unwrap();
        assert_eq!(ta.len(), tb.len());
        for (x, y) in ta.iter().zip(&tb) {
            assert_eq!(x.name, y.name);
            // Running statistics keep their own ids (burn's RunningState ignores mapped ids);
            // they are buffers, not optimizer targets.
            if !x.name.contains("running_") {
                assert_eq!(x.id, y.id, "{}", x.name);
            }
            assert_eq!(x.shape, y.shape);
            let bx: Vec<u32> = x.values.iter().map(|v| v.to_bits()).collect();
            let by: Vec<u32> = y.values.iter().map(|v| v.to_bits()).collect();
            assert_eq!(bx, by, "{}", x.name);
        }
    }

    #[test]
    fn mismatching_shapes_name_the_tensor_and_both_shapes() {
        let device = Device::flex();
        let small = ModelConfig::tiny();
        let mut wide = ModelConfig::tiny();
        wide.channels = 64;
        let bytes = weights_to_bytes(
            &StackedHourglass::new(&small, &device),
            &small,
            "stacked_hourglass",
        )
        .unwrap();
        let file = WeightsFile::parse(&bytes, Path::new("w.safetensors")).unwrap();
        let err = file
            .load_into(StackedHourglass::new(&wide, &device))
            .unwrap_err()
            .to_string();
        assert!(err.contains("w.safetensors"), "{err}");
        assert!(
            err.contains("tensor front.res3.conv3.weight: file has shape [16, 8, 1, 1], model expects [64, 32, 1, 1]"),
            "{err}"
        );
    }

    #[test]
    fn garbage_is_refused_with_the_path() {
        let err = WeightsFile::parse(b"not a tensor file", Path::new("x.safetensors"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("x.safetensors") && err.contains("not a safetensors"),
            "{err}"
        );
    }
}
