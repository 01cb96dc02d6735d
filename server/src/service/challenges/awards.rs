//! The rules of a challenge's awards, free of I/O: which rows of a task's board at the deadline
//! may win an award (from the method fields as they were then) and the sentence the page
//! writes next to it, so that the rule shown and the rule applied are the same code.

use crate::domain::{Award, BoardProtocol, Modality, ModelScope, TrainingData};
use crate::store::challenges::FrozenEntry;

/// Whether `e` may win `award` (`fast_seconds`: the challenge's threshold).
pub fn eligible(award: Award, e: &FrozenEntry, fast_seconds: f64) -> bool {
    match award {
        Award::Overall => true,
        Award::RgbOnly => {
            e.detection_modality == Some(Modality::Rgb) && e.modality == Some(Modality::Rgb)
        }
        Award::Fast => e.time.is_some_and(|t| t >= 0.0 && t < fast_seconds),
        Award::OpenSource => !e.code_url.is_empty(),
        Award::SingleModel => e.model_scope == Some(ModelScope::All),
        Award::Synthetic => e.training_data == Some(TrainingData::Synthetic),
        Award::DefaultDetections => e.detections.to_lowercase().contains("default"),
    }
}

/// The award's title, as the page heads it.
pub fn title(award: Award) -> &'static str {
    match award {
        Award::Overall => "Best overall",
        Award::RgbOnly => "Best RGB-only",
        Award::Fast => "Best fast",
        Award::OpenSource => "Best open-source",
        Award::SingleModel => "Best single-model",
        Award::Synthetic => "Best trained on synthetic images only",
        Award::DefaultDetections => "Best using the default detections",
    }
}

/// The rule of `award`, in the words the page writes next to it (the page says once what is
/// averaged, and when).
pub fn rule(award: Award, fast_seconds: f64) -> String {
    let among = match award {
        Award::Overall => "every method".to_string(),
        Award::RgbOnly => {
            "methods whose detection and pose inputs are both RGB (detection_modality and modality: rgb)"
                .to_string()
        }
        Award::Fast => format!(
            "methods whose mean time is under {fast_seconds} s per image (per target on eccv18)"
        ),
        Award::OpenSource => "methods with a code link (code_url)".to_string(),
        Award::SingleModel => "methods with one model for all objects (model_scope: all)".to_string(),
        Award::Synthetic => "methods trained on synthetic images only (training_data: synthetic)".to_string(),
        Award::DefaultDetections => {
            "methods whose detections used name the default detections (the word `default`)"
                .to_string()
        }
    };
    format!("The highest average among {among}.")
}

/// The row winning `award` on the board of `protocol`: the highest average among the eligible
/// rows with an average (a score on every dataset of the group); ties go to the method name
/// first in order, so that the winner never depends on the order rows were stored in.
pub fn winner(
    award: Award,
    protocol: BoardProtocol,
    entries: &[FrozenEntry],
    fast_seconds: f64,
) -> Option<&FrozenEntry> {
    entries
        .iter()
        .filter(|e| e.protocol == protocol && eligible(award, e, fast_seconds))
        .filter_map(|e| Some((e.average.filter(|a| a.is_finite())?, e)))
        .max_by(|(a, x), (b, y)| a.total_cmp(b).then_with(|| y.method.cmp(&x.method)))
        .map(|(_, e)| e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::MethodId;
    use evaluator::protocol::ProtocolName;

    fn entry(id: i64, method: &str, average: f64) -> FrozenEntry {
        FrozenEntry {
            protocol: BoardProtocol::Pose(ProtocolName::Bop19),
            method_id: MethodId::new(id),
            method: method.into(),
            owner: "someone".into(),
            average: Some(average),
            time: None,
            training_data: None,
            detection_modality: None,
            modality: None,
            code_url: String::new(),
            model_scope: None,
            detections: String::new(),
        }
    }

    #[test]
    fn each_award_follows_its_method_field() {
        let bop19 = BoardProtocol::Pose(ProtocolName::Bop19);
        let depth = FrozenEntry {
            modality: Some(Modality::RgbD),
            detection_modality: Some(Modality::Rgb),
            time: Some(3.0),
            ..entry(1, "depth-best", 0.9)
        };
        let rgb = FrozenEntry {
            modality: Some(Modality::Rgb),
            detection_modality: Some(Modality::Rgb),
            time: Some(0.4),
            code_url: "https://github.com/x/y".into(),
            model_scope: Some(ModelScope::All),
            training_data: Some(TrainingData::Synthetic),
            detections: "CNOS (default detections of BOP'23)".into(),
            ..entry(2, "rgb-fast", 0.6)
        };
        // Unranked: no average, so it wins nothing, however its fields read.
        let partial = FrozenEntry {
            average: None,
            ..rgb.clone()
        };
        let entries = [depth, rgb, partial];
        let won = |award| winner(award, bop19, &entries, 1.0).map(|e| e.method.as_str());
        assert_eq!(won(Award::Overall), Some("depth-best"));
        for award in [
            Award::RgbOnly,
            Award::Fast,
            Award::OpenSource,
            Award::SingleModel,
            Award::Synthetic,
            Award::DefaultDetections,
        ] {
            assert_eq!(won(award), Some("rgb-fast"), "{award}");
        }
        // A threshold under every time: nobody is fast.
        assert_eq!(winner(Award::Fast, bop19, &entries, 0.1), None);
        // Another task's board has no rows here.
        assert_eq!(
            winner(Award::Overall, BoardProtocol::Bop24, &entries, 1.0),
            None
        );
    }

    #[test]
    fn ties_go_to_the_first_name() {
        let bop19 = BoardProtocol::Pose(ProtocolName::Bop19);
        let entries = [entry(1, "zeta", 0.5), entry(2, "alpha", 0.5)];
        assert_eq!(
            winner(Award::Overall, bop19, &entries, 1.0).map(|e| e.method.as_str()),
            Some("alpha")
        );
    }
}
