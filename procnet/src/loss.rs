//! The segmentation losses of the paper (`reference/PROCNET.md`, "Losses and training").

use burn::tensor::Tensor;
use burn::tensor::activation::{log_sigmoid, sigmoid};

/// Dice loss per sample and class, `1 - (2 sum(p y) + 1) / (sum p + sum y + 1)`.
///
/// # Shapes
/// `p, y: [b, classes, h, w]` -> `[b, classes]`
pub fn dice_per_class(p: Tensor<4>, y: Tensor<4>) -> Tensor<2> {
    let [b, c, _, _] = p.dims();
    let p = p.reshape([b as i32, c as i32, -1]);
    let y = y.reshape([b as i32, c as i32, -1]);
    let intersection = (p.clone() * y.clone()).sum_dim(2);
    let total = p.sum_dim(2) + y.sum_dim(2);
    let dice: Tensor<3> = (intersection * 2.0 + 1.0) / (total + 1.0);
    dice.neg().add_scalar(1.0).reshape([b, c])
}

/// Batch Dice loss per class: the whole batch as one volume,
/// `1 - (2 sum_b(p y) + 1) / (sum_b p + sum_b y + 1)`. A frame where a part is small or absent
/// then weighs by its pixels rather than as much as a frame where the part fills the view, and
/// an empty frame's false positives are not scored against a smoothing term alone.
///
/// # Shapes
/// `p, y: [b, classes, h, w]` -> `[1, classes]`
pub fn batch_dice_per_class(p: Tensor<4>, y: Tensor<4>) -> Tensor<2> {
    let [b, c, h, w] = p.dims();
    // [b, c, h, w] -> [1, c, b h, w]: one sample whose rows are the frames' rows.
    let volume = |t: Tensor<4>| t.swap_dims(0, 1).reshape([1, c, b * h, w]);
    dice_per_class(volume(p), volume(y))
}

/// Focal loss per sample and class, averaged over pixels:
/// `-|y - p|^gamma [alpha y log p + (1 - alpha)(1 - y) log(1 - p)]`, computed from logits
/// so that it stays finite when p saturates.
///
/// # Shapes
/// `logits, y: [b, classes, h, w]` -> `[b, classes]`
pub fn focal_per_class(logits: Tensor<4>, y: Tensor<4>, alpha: f32, gamma: f32) -> Tensor<2> {
    let [b, c, _, _] = logits.dims();
    let p = sigmoid(logits.clone());
    let log_p = log_sigmoid(logits.clone());
    let log_not_p = log_sigmoid(logits.neg());
    let modulation = (y.clone() - p).abs().powf_scalar(gamma);
    let ce = y.clone() * log_p * alpha + y.neg().add_scalar(1.0) * log_not_p * (1.0 - alpha);
    let focal = (modulation * ce).neg();
    focal
        .reshape([b as i32, c as i32, -1])
        .mean_dim(2)
        .reshape([b, c])
}

/// Intersection over union of thresholded masks per sample and class (1 when both are empty).
///
/// # Shapes
/// `p, y: [b, classes, h, w]` -> `[b, classes]`
pub fn iou_per_class(p: Tensor<4>, y: Tensor<4>, threshold: f32) -> Tensor<2> {
    let [b, c, _, _] = p.dims();
    let p = p
        .greater_elem(threshold)
        .float()
        .reshape([b as i32, c as i32, -1]);
    let y = y
        .greater_elem(0.5)
        .float()
        .reshape([b as i32, c as i32, -1]);
    let intersection = (p.clone() * y.clone()).sum_dim(2);
    let union = (p + y).clamp(0.0, 1.0).sum_dim(2);
    let empty = union.clone().equal_elem(0.0).float();
    let iou: Tensor<3> = (intersection + empty.clone()) / (union + empty);
    iou.reshape([b, c])
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, TensorData};

    fn tensor(values: &[f32], shape: [usize; 4]) -> Tensor<4> {
        Tensor::from_data(TensorData::new(values.to_vec(), shape), &Device::flex())
    }

    fn values(t: Tensor<2>) -> Vec<f32> {
        t.into_data().try_into_vec::<f32>().unwrap()
    }

    #[test]
    fn batch_dice_pools_the_frames_and_equals_frame_dice_for_one_frame() {
        // Two 1x2 frames, one class. Frame 0: prediction (1, 0) against truth (1, 0);
        // frame 1: prediction (0.5, 0) against truth (0, 1).
        let p = tensor(&[1.0, 0.0, 0.5, 0.0], [2, 1, 1, 2]);
        let y = tensor(&[1.0, 0.0, 0.0, 1.0], [2, 1, 1, 2]);
        // Per frame: 1 - 3/3 = 0 and 1 - 1/2.5 = 0.6.
        let per_frame = values(dice_per_class(p.clone(), y.clone()));
        assert!((per_frame[0] - 0.0).abs() < 1e-6 && (per_frame[1] - 0.6).abs() < 1e-6);
        // As one volume: sum p y = 1, sum p = 1.5, sum y = 2: 1 - 3/4.5.
        let pooled = values(batch_dice_per_class(p.clone(), y.clone()));
        assert_eq!(pooled.len(), 1);
        assert!((pooled[0] - (1.0 - 3.0 / 4.5)).abs() < 1e-6, "{pooled:?}");
        // A batch of one frame: the two agree.
        let (p1, y1) = (p.slice([1..2, 0..1]), y.slice([1..2, 0..1]));
        assert_eq!(
            values(batch_dice_per_class(p1.clone(), y1.clone())),
            values(dice_per_class(p1, y1))
        );
    }

    #[test]
    fn batch_dice_keeps_the_classes_apart() {
        // Two classes; class 1 is predicted perfectly, class 0 not at all.
        let p = tensor(&[0.0, 0.0, 1.0, 1.0], [1, 2, 1, 2]);
        let y = tensor(&[1.0, 1.0, 1.0, 1.0], [1, 2, 1, 2]);
        let d = values(batch_dice_per_class(p, y));
        assert!(
            (d[0] - (1.0 - 1.0 / 3.0)).abs() < 1e-6 && d[1].abs() < 1e-6,
            "{d:?}"
        );
    }
}
