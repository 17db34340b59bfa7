//! The training log, `<output>.log.jsonl`: one JSON object per line, written by `pixguide train`
//! and read back by `pixguide plot-training` (docs/training.md).

/// One line of `<output>.log.jsonl` (read back by `pixguide plot-training`). Non-finite losses
/// come out as `null`, which serde_json writes for them.
#[derive(serde::Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum LogLine<'a> {
    Stage {
        stage: usize,
        kind: &'a str,
        steps: usize,
        from_step: usize,
        steps_per_epoch: usize,
        lr_rest: Option<f64>,
        lr_e: Option<f64>,
    },
    Step {
        stage: usize,
        step: usize,
        loss: f64,
        seconds: f64,
    },
    /// `by_spp`: [spp, relMSE] pairs, the same measure at each of the dataset's sample counts.
    Val {
        stage: usize,
        step: usize,
        total_step: usize,
        rel_mse: f64,
        by_spp: Vec<(usize, f64)>,
        best: bool,
        seconds: f64,
    },
    Checkpoint {
        dir: String,
    },
    StageEnd {
        stage: usize,
        steps: usize,
        reason: &'a str,
    },
}

/// `v` to `digits` decimals: timings are logged no finer than they are measured.
pub fn rounded(v: f64, digits: i32) -> f64 {
    let k = 10f64.powi(digits);
    (v * k).round() / k
}

#[cfg(test)]
mod tests {
    use super::{rounded, LogLine};

    /// The log lines read exactly as the hand-written JSON they replaced.
    #[test]
    fn log_lines_keep_their_text() {
        let line = |l: LogLine| serde_json::to_string(&l).unwrap();
        let stage =
            LogLine::Stage { stage: 0, kind: "branches", steps: 50, from_step: 0, steps_per_epoch: 5, lr_rest: Some(0.001), lr_e: None };
        assert_eq!(
            line(stage),
            r#"{"event":"stage","stage":0,"kind":"branches","steps":50,"from_step":0,"steps_per_epoch":5,"lr_rest":0.001,"lr_e":null}"#
        );
        let step = LogLine::Step { stage: 1, step: 7, loss: f64::NAN, seconds: rounded(0.123_456, 4) };
        assert_eq!(line(step), r#"{"event":"step","stage":1,"step":7,"loss":null,"seconds":0.1235}"#);
        let val = LogLine::Val {
            stage: 1,
            step: 7,
            total_step: 9,
            rel_mse: 0.0125,
            by_spp: vec![(2, 0.02), (64, 0.005)],
            best: true,
            seconds: rounded(12.345_6, 2),
        };
        assert_eq!(
            line(val),
            r#"{"event":"val","stage":1,"step":7,"total_step":9,"rel_mse":0.0125,"by_spp":[[2,0.02],[64,0.005]],"best":true,"seconds":12.35}"#
        );
        assert_eq!(line(LogLine::Checkpoint { dir: "a \"b\"".into() }), r#"{"event":"checkpoint","dir":"a \"b\""}"#);
        assert_eq!(
            line(LogLine::StageEnd { stage: 0, steps: 10, reason: "steps done" }),
            r#"{"event":"stage_end","stage":0,"steps":10,"reason":"steps done"}"#
        );
    }
}
