//! Helpers shared by the integration tests: the project's MLPs rebuilt in candle, so
//! hand-written gradients can be checked against autograd.

#![allow(dead_code)]

use candle_core::backprop::GradStore;
use candle_core::{Device, Tensor, Var};

/// The same MLP in candle: weights as variables, `tanh` on hidden layers.
pub fn candle_mlp(
    mlp: &schrl::nn::mlp::TanhMlp,
    params: &[f32],
    x: &Tensor,
) -> candle_core::Result<(Tensor, Vec<(Var, Var)>)> {
    let mut h = x.clone();
    let mut vars = Vec::new();
    for l in 0..mlp.num_layers() {
        let (i, o) = (mlp.sizes()[l], mlp.sizes()[l + 1]);
        let (wr, br) = mlp.layer_ranges(l);
        let w = Var::from_tensor(&Tensor::from_slice(&params[wr], (o, i), &Device::Cpu)?)?;
        let b = Var::from_tensor(&Tensor::from_slice(&params[br], o, &Device::Cpu)?)?;
        h = h.matmul(&w.as_tensor().t()?)?.broadcast_add(b.as_tensor())?;
        if l + 1 < mlp.num_layers() {
            h = h.tanh()?;
        }
        vars.push((w, b));
    }
    Ok((h, vars))
}

/// The gradients of `vars` in `g`, flattened in the project's parameter layout (each
/// layer's weights, then its biases).
pub fn flat_grads(g: &GradStore, vars: &[(Var, Var)]) -> candle_core::Result<Vec<f32>> {
    let mut out = Vec::new();
    for (w, b) in vars {
        for v in [w, b] {
            out.extend(g.get(v.as_tensor()).expect("gradient").flatten_all()?.to_vec1::<f32>()?);
        }
    }
    Ok(out)
}

/// `hand` equals `autograd` within `rel` of the largest autograd magnitude (≥ 1).
pub fn assert_grads_close(hand: &[f32], autograd: &[f32], rel: f32, what: &str) {
    assert_eq!(hand.len(), autograd.len(), "{what}: lengths");
    let scale = autograd.iter().fold(1.0f32, |a, b| a.max(b.abs()));
    for (i, (a, b)) in hand.iter().zip(autograd).enumerate() {
        assert!((a - b).abs() <= rel * scale, "{what} parameter {i}: hand-written {a}, candle {b}");
    }
}
