//! The fused update's access to the candle parameters: the networks read as
//! flat slices without a copy, and Adam and the Polyak average applied in
//! place. The `Var`s stay the one home of the parameters (checkpoints, export,
//! acting, the candle reference path all read them).

use std::ops::Range;

use candle_core::{
    bail, CpuStorage, InplaceOp1, InplaceOp2, InplaceOp3, Layout, Result, Storage, StorageRef,
    Tensor, Var,
};

use crate::fused::{LayerRef, NetGradient};
use crate::nets::Mlp;

/// An in-place op over f32 storage: `f(dst, sources)`.
struct InPlace<F>(F);

fn contiguous_f32<'a>(storage: &'a CpuStorage, layout: &Layout) -> Result<&'a [f32]> {
    match (storage, layout.contiguous_offsets()) {
        (CpuStorage::F32(v), Some((a, b))) => Ok(&v[a..b]),
        _ => bail!("a parameter is not a contiguous f32 tensor"),
    }
}

impl<F> InPlace<F> {
    fn apply<const N: usize>(
        &self,
        dst: &mut CpuStorage,
        dst_l: &Layout,
        srcs: [(&CpuStorage, &Layout); N],
    ) -> Result<()>
    where
        F: Fn(&mut [f32], [&[f32]; N]),
    {
        let mut sources = [&[][..]; N];
        for (s, (storage, layout)) in sources.iter_mut().zip(srcs) {
            *s = contiguous_f32(storage, layout)?;
        }
        match (dst, dst_l.contiguous_offsets()) {
            (CpuStorage::F32(v), Some((a, b))) => {
                (self.0)(&mut v[a..b], sources);
                Ok(())
            }
            _ => bail!("a parameter is not a contiguous f32 tensor"),
        }
    }
}

const OP_NAME: &str = "fused-parameter-update";

impl<F: Fn(&mut [f32], [&[f32]; 0])> InplaceOp1 for InPlace<F> {
    fn name(&self) -> &'static str {
        OP_NAME
    }

    fn cpu_fwd(&self, dst: &mut CpuStorage, l: &Layout) -> Result<()> {
        self.apply(dst, l, [])
    }
}

impl<F: Fn(&mut [f32], [&[f32]; 1])> InplaceOp2 for InPlace<F> {
    fn name(&self) -> &'static str {
        OP_NAME
    }

    fn cpu_fwd(&self, dst: &mut CpuStorage, l: &Layout, s: &CpuStorage, sl: &Layout) -> Result<()> {
        self.apply(dst, l, [(s, sl)])
    }
}

impl<F: Fn(&mut [f32], [&[f32]; 2])> InplaceOp3 for InPlace<F> {
    fn name(&self) -> &'static str {
        OP_NAME
    }

    fn cpu_fwd(
        &self,
        dst: &mut CpuStorage,
        l: &Layout,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> Result<()> {
        self.apply(dst, l, [(s1, l1), (s2, l2)])
    }
}

/// Read locks on a set of networks' parameters, for [`ReadParams::layers`].
pub struct ReadParams<'a> {
    /// Per network, per layer: (weight, bias) storage and offsets.
    nets: Vec<Vec<[Locked<'a>; 2]>>,
}

/// A read-locked storage and the tensor's range in it.
type Locked<'a> = (StorageRef<'a>, Range<usize>);

fn read(t: &Tensor) -> Result<Locked<'_>> {
    let (storage, layout) = t.storage_and_layout();
    let Some((a, b)) = layout.contiguous_offsets() else {
        bail!("a parameter is not contiguous");
    };
    Ok((storage, a..b))
}

impl<'a> ReadParams<'a> {
    pub fn new(nets: &[&'a Mlp]) -> Result<Self> {
        let nets = nets
            .iter()
            .map(|net| {
                net.layers
                    .iter()
                    .map(|(w, b)| Ok([read(w.as_tensor())?, read(b.as_tensor())?]))
                    .collect::<Result<_>>()
            })
            .collect::<Result<_>>()?;
        Ok(Self { nets })
    }

    /// Network `i`'s layers as slices.
    pub fn layers(&self, i: usize) -> Result<Vec<LayerRef<'_>>> {
        fn slice<'b>((storage, range): &'b Locked<'_>) -> Result<&'b [f32]> {
            match &**storage {
                Storage::Cpu(CpuStorage::F32(v)) => Ok(&v[range.clone()]),
                _ => bail!("a parameter is not an f32 tensor on the CPU"),
            }
        }
        self.nets[i]
            .iter()
            .map(|[w, b]| {
                Ok(LayerRef {
                    weight: slice(w)?,
                    bias: slice(b)?,
                })
            })
            .collect()
    }
}

/// The gradient of `vars[i]` (laid out as [`Mlp::vars`]: w₀, b₀, w₁, b₁, …).
fn var_gradient(grad: &NetGradient, i: usize) -> &[f32] {
    let (w, b) = &grad.layers[i / 2];
    if i.is_multiple_of(2) {
        w
    } else {
        b
    }
}

/// One Adam step (agent::Adam::step, the same operations in the same order in
/// f32) with a flat gradient, in place.
pub fn adam_step(
    vars: &[Var],
    (m, v): (&[Var], &[Var]),
    grad: &NetGradient,
    (lr, c1, c2): (f64, f64, f64),
    (beta1, beta2, eps): (f64, f64, f64),
) -> Result<()> {
    let f = |x: f64| x as f32;
    for (i, ((var, m), v)) in vars.iter().zip(m).zip(v).enumerate() {
        let g = var_gradient(grad, i);
        m.as_tensor()
            .inplace_op1(&InPlace(|m: &mut [f32], []: [&[f32]; 0]| {
                for (m, g) in m.iter_mut().zip(g) {
                    *m = *m * f(beta1) + g * f(1.0 - beta1);
                }
            }))?;
        v.as_tensor()
            .inplace_op1(&InPlace(|v: &mut [f32], []: [&[f32]; 0]| {
                for (v, g) in v.iter_mut().zip(g) {
                    *v = *v * f(beta2) + (g * g) * f(1.0 - beta2);
                }
            }))?;
        var.as_tensor().inplace_op3(
            m.as_tensor(),
            v.as_tensor(),
            &InPlace(|p: &mut [f32], [m, v]: [&[f32]; 2]| {
                for ((p, m), v) in p.iter_mut().zip(m).zip(v) {
                    let denom = (v / f(c2)).sqrt() + f(eps);
                    *p -= (m / f(c1)) / denom * f(lr);
                }
            }),
        )?;
    }
    Ok(())
}

/// θ_target ← (1 − τ) θ_target + τ θ (nets::Mlp::polyak_from), in place.
pub fn polyak(target: &Mlp, source: &Mlp, tau: f64) -> Result<()> {
    let (keep, take) = ((1.0 - tau) as f32, tau as f32);
    for ((w, b), (sw, sb)) in target.layers.iter().zip(&source.layers) {
        for (dst, src) in [(w, sw), (b, sb)] {
            dst.as_tensor().inplace_op2(
                src.as_tensor(),
                &InPlace(|d: &mut [f32], [s]: [&[f32]; 1]| {
                    for (d, s) in d.iter_mut().zip(s) {
                        *d = *d * keep + s * take;
                    }
                }),
            )?;
        }
    }
    Ok(())
}
