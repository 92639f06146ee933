//! The result columns every study writes, whatever its device: where each task sits in the grid
//! with its fit (`tasks.parquet`'s first columns) and the identified parameters in long form
//! (`parameters.parquet`).

use polars::prelude::Column;

use crate::robot::{ParamSet, RobotModel};
use crate::study::engine::{Identified, Task};

/// The columns every study's `tasks.parquet` starts with: where the task sits in the grid, the set
/// chosen and how the fit ended.
pub fn task_columns<'a>(rows: impl Iterator<Item = (&'a Task, &'a Identified)> + Clone) -> Vec<Column> {
    let u32c = |name: &str, f: &dyn Fn(&Task, &Identified) -> u32| {
        Column::new(name.into(), rows.clone().map(|(t, i)| f(t, i)).collect::<Vec<_>>())
    };
    let f64c = |name: &str, f: &dyn Fn(&Identified) -> f64| Column::new(name.into(), rows.clone().map(|(_, i)| f(i)).collect::<Vec<_>>());
    let strc = |name: &str, f: &dyn Fn(&Task, &Identified) -> String| {
        Column::new(name.into(), rows.clone().map(|(t, i)| f(t, i)).collect::<Vec<_>>())
    };
    vec![
        u32c("task", &|t, _| t.index as u32),
        strc("selection", &|t, _| t.selection.label().to_string()),
        u32c("set_size", &|t, _| t.set_size as u32),
        u32c("repetition", &|t, _| t.repetition as u32),
        f64c("o1", &|i| i.observability.o1),
        f64c("o2", &|i| i.observability.o2),
        f64c("o3", &|i| i.observability.o3),
        f64c("o4", &|i| i.observability.o4),
        f64c("o5", &|i| i.observability.o5),
        f64c("condition_number", &|i| i.condition_number),
        strc("outcome", &|_, i| i.outcome.label().to_string()),
        strc("unidentifiable", &|_, i| i.outcome.unidentifiable().join(" ")),
        u32c("iterations", &|_, i| i.iterations as u32),
        u32c("detmax_steps", &|_, i| i.detmax_steps as u32),
        f64c("residual_rms_mm", &|i| i.residual_rms_mm),
    ]
}

/// `parameters.parquet` of any study: one row per task and identified parameter, in the unit of the
/// paper's tables, beside the truth and the nominal (start) value.
pub fn parameter_columns<'a>(
    set: &ParamSet,
    rows: impl Iterator<Item = (&'a Task, &'a Identified)>,
    truth: &RobotModel,
    nominal: &RobotModel,
) -> Vec<Column> {
    let ids = set.ids();
    let in_unit = |id: &crate::robot::ParamId, m: &RobotModel| id.unit().from_internal(id.get(m.data()));
    let (truth_v, nominal_v): (Vec<f64>, Vec<f64>) = ids.iter().map(|id| (in_unit(id, truth), in_unit(id, nominal))).unzip();
    let (mut task, mut param, mut unit, mut value, mut tv, mut nv) = (vec![], vec![], vec![], vec![], vec![], vec![]);
    for (t, x) in rows {
        for (j, id) in ids.iter().enumerate() {
            task.push(t.index as u32);
            param.push(id.name());
            unit.push(id.unit().symbol().to_string());
            value.push(x.values[j].map(|v| id.unit().from_internal(v)));
            tv.push(truth_v[j]);
            nv.push(nominal_v[j]);
        }
    }
    vec![
        Column::new("task".into(), task),
        Column::new("parameter".into(), param),
        Column::new("unit".into(), unit),
        Column::new("identified".into(), value),
        Column::new("truth".into(), tv),
        Column::new("nominal".into(), nv),
    ]
}
