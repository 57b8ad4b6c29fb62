//! The stacked hourglass network of DeepVPCalib (Kocur & Ftáčnik, ICANN 2021, §4), after
//! Newell et al., "Stacked Hourglass Networks for Human Pose Estimation" (ECCV 2016), with the
//! reference code's layer order (DESIGN.md §5).
//!
//! ```text
//! crop 3xSxS -> front: conv7x7 (stride 1) ReLU BN -> res(C/2) -> maxpool2 -> res(C/2) -> res(C)
//!            -> stack 1 -> stack 2 -> ... (each emits K heatmaps, all supervised)
//! stack(x): y = hourglass(x); h = BN(ReLU(conv1x1(y))); out = conv1x1(h) (linear, K channels)
//!           next = conv1x1(h) + conv1x1(out) + x           (not built for the last stack)
//! residual(C): main = [1x1 C/2, ReLU, BN] [3x3 C/2, ReLU, BN] [1x1 C, ReLU, BN]
//!              skip = identity, or 1x1 conv + ReLU (no BN) when channels differ; out = skip + main
//! hourglass: left f0..f(d-1) = res, pool, res, pool, ..., res   (64 -> 32 -> 16 -> 8)
//!            bottom r = res(f) + res(res(res(f)))
//!            up r_i = res(res(f_i) + upsample_nearest(r_(i+1)))
//! ```
//! Weight names mirror the structure (`front.res1.conv2.weight`, `stacks.1.hourglass.up.0.conv1.bias`,
//! `stacks.0.next_head.weight`), so checkpoints load without a renaming table.
//!
//! Heatmap post-processing (diamond-space decoding) lives in `vpcal_geom::heatmap`, not here.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, PaddingConfig2d};
use burn::tensor::activation::relu;
use burn::tensor::module::{interpolate, max_pool2d};
use burn::tensor::ops::{InterpolateMode, InterpolateOptions, MaxPoolOptions};
use burn::tensor::{Device, Tensor};

use crate::config::{ChannelOrder, ModelConfig, Normalisation};

fn conv(cin: usize, cout: usize, kernel: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new([cin, cout], [kernel, kernel])
        .with_padding(PaddingConfig2d::Same)
        .init(device)
}

/// `conv` applied to `x`. While training, a pointwise convolution (1x1, stride 1, one group,
/// no padding) is computed as a matrix product over the pixels (the same sums): its weight
/// gradient is then a few large products, where burn's convolution backward spent a fifth of
/// a training step in matrix-vector products (docs/network.md, "Speed"). For inference
/// burn's own 1x1 convolution is faster.
///
/// # Shapes
/// - `x`: `[batch, cin, h, w]`
/// - output: `[batch, cout, h', w']`
pub(crate) fn apply(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    let weight = conv.weight.val(); // [cout, cin / groups, k, k]
    let [cout, cin, _, _] = weight.dims();
    let pointwise = conv.kernel_size == [1, 1]
        && conv.stride == [1, 1]
        && conv.groups == 1
        && matches!(
            conv.padding,
            PaddingConfig2d::Same | PaddingConfig2d::Valid | PaddingConfig2d::Explicit(0, 0, 0, 0)
        );
    if !pointwise || !weight.is_require_grad() {
        return conv.forward(x);
    }
    let [b, _, h, w] = x.dims();
    let y = weight
        .reshape([1, cout, cin])
        .matmul(x.reshape([b, cin, h * w])); // [b, cout, h*w]
    let y = match &conv.bias {
        Some(bias) => y + bias.val().reshape([1, cout, 1]),
        None => y,
    };
    y.reshape([b, cout, h, w])
}

fn batch_norm(channels: usize, config: &ModelConfig, device: &Device) -> BatchNorm {
    BatchNormConfig::new(channels)
        .with_momentum(config.bn_momentum)
        .with_epsilon(config.bn_epsilon)
        .init(device)
}

/// 2x2 max-pooling with stride 2.
fn pool2(x: Tensor<4>) -> Tensor<4> {
    max_pool2d(x, MaxPoolOptions::new([2, 2]).with_stride([2, 2]))
}

/// Nearest-neighbour upsampling by 2 (Keras `UpSampling2D`).
fn upsample2(x: Tensor<4>) -> Tensor<4> {
    let [_, _, h, w] = x.dims();
    interpolate(
        x,
        InterpolateOptions::new(InterpolateMode::Nearest).with_output_size([2 * h, 2 * w]),
    )
}

/// Bottleneck residual block (see the module docs).
#[derive(Module, Debug)]
pub struct Residual {
    conv1: Conv2d,
    bn1: BatchNorm,
    conv2: Conv2d,
    bn2: BatchNorm,
    conv3: Conv2d,
    bn3: BatchNorm,
    /// 1x1 projection (+ ReLU) when the input has other than `channels` channels.
    skip: Option<Conv2d>,
}

impl Residual {
    /// A block from `cin` to `cout` channels (`cout` even).
    pub fn new(cin: usize, cout: usize, config: &ModelConfig, device: &Device) -> Self {
        let half = cout / 2;
        Residual {
            conv1: conv(cin, half, 1, device),
            bn1: batch_norm(half, config, device),
            conv2: conv(half, half, 3, device),
            bn2: batch_norm(half, config, device),
            conv3: conv(half, cout, 1, device),
            bn3: batch_norm(cout, config, device),
            skip: (cin != cout).then(|| conv(cin, cout, 1, device)),
        }
    }

    /// # Shapes
    /// - `x`: `[batch, cin, h, w]`
    /// - output: `[batch, cout, h, w]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let skip = match &self.skip {
            Some(conv) => relu(apply(conv, x.clone())), // [b, cout, h, w]
            None => x.clone(),
        };
        let y = self.bn1.forward(relu(apply(&self.conv1, x))); // [b, cout/2, h, w]
        let y = self.bn2.forward(relu(apply(&self.conv2, y))); // [b, cout/2, h, w]
        let y = self.bn3.forward(relu(apply(&self.conv3, y))); // [b, cout, h, w]
        skip + y
    }
}

/// The front module: full-resolution 7x7 convolution, residual blocks and pooling down to the
/// heatmap resolution.
#[derive(Module, Debug)]
pub struct Front {
    conv: Conv2d,
    bn: BatchNorm,
    res1: Residual,
    res2: Residual,
    res3: Residual,
    pools: usize,
}

impl Front {
    fn new(config: &ModelConfig, device: &Device) -> Self {
        let c = config.channels;
        Front {
            conv: conv(3, config.front_channels, 7, device),
            bn: batch_norm(config.front_channels, config, device),
            res1: Residual::new(config.front_channels, c / 2, config, device),
            res2: Residual::new(c / 2, c / 2, config, device),
            res3: Residual::new(c / 2, c, config, device),
            pools: config.front_pools(),
        }
    }

    /// # Shapes
    /// - `x`: `[batch, 3, input, input]`
    /// - output: `[batch, channels, heatmap, heatmap]`
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = self.bn.forward(relu(self.conv.forward(x))); // [b, front, in, in]
        let mut x = self.res1.forward(x); // [b, c/2, in, in]
        for _ in 0..self.pools {
            x = pool2(x); // halves h, w down to [b, c/2, hm, hm]
        }
        let x = self.res2.forward(x); // [b, c/2, hm, hm]
        self.res3.forward(x) // [b, c, hm, hm]
    }
}

/// One hourglass of `depth` levels at constant channel count.
#[derive(Module, Debug)]
pub struct Hourglass {
    /// Left half, one block per level (full resolution first).
    down: Vec<Residual>,
    /// Bottom: the skip block, and the chain of three blocks.
    bottom_skip: Residual,
    bottom: Vec<Residual>,
    /// Right half, levels `depth-2 ..= 0` in the order they are applied: the block on the
    /// left feature, and the block after the sum.
    up_skip: Vec<Residual>,
    up: Vec<Residual>,
}

impl Hourglass {
    fn new(config: &ModelConfig, device: &Device) -> Self {
        let c = config.channels;
        let block = || Residual::new(c, c, config, device);
        let d = config.depth;
        Hourglass {
            down: (0..d).map(|_| block()).collect(),
            bottom_skip: block(),
            bottom: (0..3).map(|_| block()).collect(),
            up_skip: (1..d).map(|_| block()).collect(),
            up: (1..d).map(|_| block()).collect(),
        }
    }

    /// # Shapes
    /// - `x`: `[batch, channels, h, w]`, h and w divisible by `2^(depth-1)`
    /// - output: `[batch, channels, h, w]`
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut left = Vec::with_capacity(self.down.len());
        let mut x = x;
        for (level, block) in self.down.iter().enumerate() {
            if level > 0 {
                x = pool2(x); // [b, c, h / 2^level, w / 2^level]
            }
            x = block.forward(x);
            left.push(x.clone());
        }
        let lowest = x; // [b, c, h / 2^(d-1), w / 2^(d-1)]
        let mut y = lowest.clone();
        for block in &self.bottom {
            y = block.forward(y);
        }
        let mut r = y + self.bottom_skip.forward(lowest);
        // Walk back up: level d-2 down to 0.
        for (i, (skip, after)) in self.up_skip.iter().zip(&self.up).enumerate() {
            let level = left.len() - 2 - i;
            let f = left[level].clone(); // [b, c, h / 2^level, w / 2^level]
            r = after.forward(skip.forward(f) + upsample2(r));
        }
        r
    }
}

/// One stack: hourglass, head, supervised output and (except for the last stack) the merge
/// that feeds the next stack.
#[derive(Module, Debug)]
pub struct Stack {
    hourglass: Hourglass,
    head: Conv2d,
    head_bn: BatchNorm,
    out: Conv2d,
    /// `1x1(head)` and `1x1(out)` of the next-stage merge; `None` on the last stack.
    next_head: Option<Conv2d>,
    next_out: Option<Conv2d>,
}

impl Stack {
    fn new(last: bool, k: usize, config: &ModelConfig, device: &Device) -> Self {
        let c = config.channels;
        Stack {
            hourglass: Hourglass::new(config, device),
            head: conv(c, c, 1, device),
            head_bn: batch_norm(c, config, device),
            out: conv(c, k, 1, device),
            next_head: (!last).then(|| conv(c, c, 1, device)),
            next_out: (!last).then(|| conv(k, c, 1, device)),
        }
    }

    /// # Shapes
    /// - `x`: `[batch, channels, hm, hm]`
    /// - output: (`heatmaps [batch, outputs, hm, hm]`, `next [batch, channels, hm, hm]` unless last)
    fn forward(&self, x: Tensor<4>) -> (Tensor<4>, Option<Tensor<4>>) {
        let y = self.hourglass.forward(x.clone()); // [b, c, hm, hm]
        let head = self.head_bn.forward(relu(apply(&self.head, y))); // [b, c, hm, hm]
        let out = apply(&self.out, head.clone()); // [b, k, hm, hm]
        let next = match (&self.next_head, &self.next_out) {
            (Some(nh), Some(no)) => Some(apply(nh, head) + apply(no, out.clone()) + x),
            _ => None,
        };
        (out, next)
    }
}

/// The stacked hourglass VP network. Build it with [`StackedHourglass::new`] from a validated
/// [`ModelConfig`].
#[derive(Module, Debug)]
pub struct StackedHourglass {
    front: Front,
    stacks: Vec<Stack>,
    /// Input conventions (not weights).
    #[module(skip)]
    input: InputSpec,
}

/// What the model does to its RGB `[0, 1]` input before the first convolution.
#[derive(Debug, Clone)]
pub struct InputSpec {
    pub channel_order: ChannelOrder,
    pub normalisation: Normalisation,
}

impl StackedHourglass {
    /// A freshly initialised network (burn's default initialisers; seed the device for
    /// reproducibility). The config must be [valid](ModelConfig::validate).
    ///
    /// The last stack has no next-stage merge convolutions (the reference Keras model builds
    /// them but never uses them), so the paper network has 6,596,496 parameters counting
    /// batch-norm running statistics, as Keras counts them.
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        Self::with_outputs(config, config.outputs(), device)
    }

    /// Like [`StackedHourglass::new`] with `outputs` output channels per stack instead of
    /// `2 * scales` (the hourglass-with-pooling regression baseline uses 64).
    pub fn with_outputs(config: &ModelConfig, outputs: usize, device: &Device) -> Self {
        let stacks = (0..config.stacks)
            .map(|i| Stack::new(i + 1 == config.stacks, outputs, config, device))
            .collect();
        StackedHourglass {
            front: Front::new(config, device),
            stacks,
            input: InputSpec {
                channel_order: config.channel_order,
                normalisation: config.normalisation.clone(),
            },
        }
    }

    /// Heatmaps of every stack (intermediate supervision); the last one is the prediction.
    ///
    /// # Shapes
    /// - `images`: `[batch, 3, input, input]`, RGB in `[0, 1]` (the model applies its own
    ///   channel order and normalisation)
    /// - output: `stacks` tensors `[batch, outputs, heatmap, heatmap]`, channel order VP1 at
    ///   each scale, then VP2 at each scale
    pub fn forward(&self, images: Tensor<4>) -> Vec<Tensor<4>> {
        let x = self.prepare(images); // [b, 3, in, in]
        let mut x = self.front.forward(x); // [b, c, hm, hm]
        let mut outs = Vec::with_capacity(self.stacks.len());
        for stack in &self.stacks {
            let (out, next) = stack.forward(x.clone());
            outs.push(out); // [b, k, hm, hm]
            match next {
                Some(next) => x = next,
                None => break,
            }
        }
        outs
    }

    /// Heatmaps of the last stack only.
    ///
    /// # Shapes
    /// - `images`: `[batch, 3, input, input]`, RGB in `[0, 1]`
    /// - output: `[batch, outputs, heatmap, heatmap]`
    pub fn forward_last(&self, images: Tensor<4>) -> Tensor<4> {
        let mut outs = self.forward(images);
        // `new` builds at least one stack (validated config), so `outs` is not empty.
        match outs.pop() {
            Some(last) => last,
            None => Tensor::zeros([0, 0, 0, 0], &self.devices()[0]),
        }
    }

    fn prepare(&self, images: Tensor<4>) -> Tensor<4> {
        self.input.apply(images)
    }
}

impl InputSpec {
    /// Channel reorder and normalisation of RGB `[0, 1]` input.
    ///
    /// # Shapes
    /// - `images`: `[batch, 3, h, w]`; output: the same
    pub fn apply(&self, images: Tensor<4>) -> Tensor<4> {
        let x = match self.channel_order {
            ChannelOrder::Rgb => images,
            ChannelOrder::Bgr => images.flip([1]),
        };
        match &self.normalisation {
            Normalisation::Unit => x,
            Normalisation::MeanStd { mean, std } => {
                let device = x.device();
                let mean = Tensor::<1>::from_floats(*mean, &device).reshape([1, 3, 1, 1]);
                let inv: [f32; 3] = std.map(|s| 1.0 / s);
                let inv = Tensor::<1>::from_floats(inv, &device).reshape([1, 3, 1, 1]);
                (x - mean) * inv
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parameter count of one residual block, written out independently of the model code
    /// (Keras convention: conv weights + biases, 4 values per batch-norm channel).
    fn block(cin: usize, c: usize) -> usize {
        let h = c / 2;
        let convs = cin * h + h + 9 * h * h + h + h * c + c;
        let bns = 4 * (h + h + c);
        let skip = if cin == c { 0 } else { cin * c + c };
        convs + bns + skip
    }

    #[test]
    fn paper_parameter_count() {
        let (c, k) = (256, 8);
        let front = 3 * 49 * 64 + 64 + 4 * 64 + block(64, 128) + block(128, 128) + block(128, 256);
        let hourglass = 14 * block(c, c); // 4 down, 1 + 3 bottom, 2 x 3 up
        let head = c * c + c + 4 * c + c * k + k;
        let merge = c * c + c + k * c + c;
        let expected = front + 2 * (hourglass + head) + merge;
        assert_eq!(expected, 6_596_496);
        let model = StackedHourglass::new(&ModelConfig::paper(), &Device::flex());
        assert_eq!(model.num_params(), expected);
        let tiny = StackedHourglass::new(&ModelConfig::tiny(), &Device::flex());
        assert_eq!(tiny.num_params(), 20_096);
        let small = StackedHourglass::new(&ModelConfig::small(), &Device::flex());
        assert_eq!(small.num_params(), 92_848);
    }

    /// The matrix-product form of a 1x1 convolution gives burn's convolution, with and
    /// without bias; other kernels go through the convolution itself.
    #[test]
    fn pointwise_convolutions_are_the_convolutions() {
        // A training device: its parameters require gradients.
        let device = Device::flex().autodiff();
        let x = Tensor::<4>::random(
            [2, 5, 6, 7],
            burn::tensor::Distribution::Normal(0.0, 1.0),
            &device,
        );
        for (kernel, bias) in [(1, true), (1, false), (3, true)] {
            let conv = Conv2dConfig::new([5, 4], [kernel, kernel])
                .with_padding(PaddingConfig2d::Same)
                .with_bias(bias)
                .init(&device);
            let weight = conv.weight.val();
            assert!(weight.is_require_grad());
            let want = conv.forward(x.clone());
            let got = apply(&conv, x.clone());
            assert_eq!(got.dims(), want.dims());
            let diff: f32 = (got.clone() - want.clone()).abs().max().into_scalar();
            assert!(diff < 1e-5, "kernel {kernel}, bias {bias}: {diff}");
            // And so are the weights' gradients.
            let grad = |y: Tensor<4>| {
                let grads = (y.clone() * y).sum().backward();
                weight.grad(&grads).expect("a gradient")
            };
            let diff: f32 = (grad(got) - grad(want)).abs().max().into_scalar();
            assert!(diff < 1e-3, "kernel {kernel}, bias {bias}: gradient {diff}");
        }
    }

    #[test]
    fn tiny_forward_shapes() {
        let config = ModelConfig::tiny();
        let device = Device::flex();
        let model = StackedHourglass::new(&config, &device);
        let x = Tensor::<4>::zeros([2, 3, config.input_size, config.input_size], &device);
        let outs = model.forward(x);
        assert_eq!(outs.len(), config.stacks);
        for out in outs {
            assert_eq!(
                out.dims(),
                [
                    2,
                    config.outputs(),
                    config.heatmap_size,
                    config.heatmap_size
                ]
            );
        }
    }
}
