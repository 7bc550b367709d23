//! The candle bridge: batched robustness whose gradient reaches paths and neural
//! predicate parameters.
#![cfg(feature = "candle")]

mod common;

use candle_core::{DType, Device, Tensor, Var};
use stl::tensor::TensorSpec;
use stl::{Ball, Halfspace, Semantics, parse};

const SRC: &str = "F[1,2] a & G[1,3] !b | (x > 0.3 U[0,2] c)";

fn tensor_spec() -> TensorSpec {
    TensorSpec::builder(parse(SRC).unwrap(), 2)
        .signals(["x", "y"])
        .bind_predicate("a", Ball::new([1.0, 0.0], 0.5))
        .bind_predicate("b", Ball::new([0.0, 1.0], 0.7))
        .bind_predicate("c", Halfspace { normal: vec![1.0, -0.5], bound: 0.2 })
        .build()
        .unwrap()
}

#[test]
fn tensor_robustness_and_gradient_equal_the_scalar_spec() {
    let (b, t) = (6, 5);
    let data: Vec<f64> = (0..b * t * 2).map(|i| ((i * 7919) % 89) as f64 / 25.0 - 1.7).collect();
    let spec = common::bind(parse(SRC).unwrap());
    let ts = tensor_spec();
    for sem in [Semantics::hard(), Semantics::soft(2.0), Semantics::lse(0.5)] {
        let paths =
            Var::from_tensor(&Tensor::from_vec(data.clone(), (b, t, 2), &Device::Cpu).unwrap()).unwrap();
        let rho = ts.robustness(paths.as_tensor(), &sem).unwrap();
        // Weight paths differently so that the batch gradient is not symmetric.
        let w = Tensor::from_vec((1..=b).map(|i| i as f64).collect::<Vec<_>>(), b, &Device::Cpu).unwrap();
        let grads = (rho.clone() * w).unwrap().sum_all().unwrap().backward().unwrap();
        let g: Vec<f64> = grads.get(paths.as_tensor()).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        let rho: Vec<f64> = rho.to_vec1().unwrap();
        for (i, p) in data.chunks(t * 2).enumerate() {
            let (r, gs) = spec.gradient(p, &sem).unwrap();
            assert!((rho[i] - r).abs() < 1e-12, "{sem}");
            for (a, e) in g[i * t * 2..(i + 1) * t * 2].iter().zip(&gs) {
                assert!((a - e * (i + 1) as f64).abs() < 1e-9, "{sem}: {a} vs {e}");
            }
        }
    }
}

#[test]
fn neural_predicate_parameters_receive_gradients() {
    // A linear "network" w·p + bias as the obstacle predicate, trainable.
    let dev = Device::Cpu;
    let w = Var::from_tensor(&Tensor::new(&[[0.7f32], [-0.3]], &dev).unwrap()).unwrap();
    let bias = Var::from_tensor(&Tensor::new(&[0.1f32], &dev).unwrap()).unwrap();
    let (wc, bc) = (w.as_tensor().clone(), bias.as_tensor().clone());
    let net = move |paths: &Tensor| -> candle_core::Result<Tensor> {
        let (b, t, d) = paths.dims3()?;
        paths.reshape((b * t, d))?.matmul(&wc)?.broadcast_add(&bc)?.reshape((b, t))
    };
    let spec = TensorSpec::builder(parse("G[1,3] safe & F[1,3] goal").unwrap(), 2)
        .bind("safe", net)
        .bind_predicate("goal", Ball::new([1.0, 1.0], 0.5))
        .build()
        .unwrap();
    let paths = Var::from_tensor(&Tensor::randn(0f32, 1.0, (8, 4, 2), &dev).unwrap()).unwrap();
    let sem = Semantics::soft(2.0);
    let loss = spec.robustness(paths.as_tensor(), &sem).unwrap().sum_all().unwrap();
    let grads = loss.backward().unwrap();
    let gw: Vec<f32> =
        grads.get(w.as_tensor()).expect("weights get a gradient").flatten_all().unwrap().to_vec1().unwrap();
    let gb: Vec<f32> = grads.get(bias.as_tensor()).expect("bias gets a gradient").to_vec1().unwrap();
    assert!(gw.iter().any(|g| g.abs() > 1e-4) && gb[0].abs() > 1e-4, "{gw:?} {gb:?}");
    // Finite difference on the bias.
    let eval = |db: f32| {
        bias.set(&Tensor::new(&[0.1f32 + db], &dev).unwrap()).unwrap();
        let r: f32 =
            spec.robustness(paths.as_tensor(), &sem).unwrap().sum_all().unwrap().to_scalar().unwrap();
        r
    };
    let fd = (eval(1e-2) - eval(-1e-2)) / 2e-2;
    assert!((fd - gb[0]).abs() < 2e-2 * (1.0 + fd.abs()), "{fd} vs {}", gb[0]);
    assert!(paths.as_tensor().dtype() == DType::F32);
}

#[test]
fn wrong_shapes_are_errors() {
    let ts = tensor_spec();
    let bad = Tensor::zeros((2, 3, 3), DType::F32, &Device::Cpu).unwrap();
    assert!(ts.robustness(&bad, &Semantics::hard()).is_err());
    let bad = Tensor::zeros((2, 3), DType::F32, &Device::Cpu).unwrap();
    assert!(ts.robustness(&bad, &Semantics::hard()).is_err());
}
