//! Groups of datasets: the columns a board ranks by, as the BOP site ranks over
//! BOP-Classic-Core, BOP-Industrial or BOP-H3. A board without `?group=` ranks over the default
//! group, `core`: the core datasets (set by `--core-datasets` and the datasets page's toggle,
//! else the default rule of [`core_datasets`]), so every board and link from before groups
//! keeps its columns. Other groups are stored by name with their members' names; a board shows
//! the members served (not retired), so a group may name a dataset not served yet.
//!
//! Administrators create, replace and delete groups (audited). These are the functions a
//! challenge reuses to name the groups it ranks over.

use serde::Serialize;

use crate::app::App;
use crate::domain::{DEFAULT_GROUP, DEMO_DATASET, DatasetName, GroupName};
use crate::error::{AppError, AppResult};
use crate::store::accounts::User;
use crate::store::audit::AdminAction;
use crate::store::datasets::DatasetRow;
use crate::store::groups::GroupRow;

/// Most datasets one group names (BOP has fewer than twenty).
pub const MAX_MEMBERS: usize = 100;

/// A group of datasets as readers see it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Group {
    pub name: String,
    /// The group a board ranks by without `?group=`: the core datasets.
    pub default: bool,
    /// Its members by name, served here or not.
    pub datasets: Vec<String>,
    /// The members served (not retired): the columns of its boards.
    pub served: Vec<String>,
}

/// The core datasets: those flagged core, and of those never flagged, every one but the demo
/// dataset once another is served (the demo is there to try the service, not to rank methods).
pub fn core_datasets(datasets: &[DatasetRow]) -> Vec<DatasetRow> {
    let others = datasets.iter().any(|d| d.name != DEMO_DATASET);
    datasets
        .iter()
        .filter(|d| d.core.unwrap_or(!(others && d.name == DEMO_DATASET)))
        .cloned()
        .collect()
}

/// The group of a board: its name and its columns (the served members, by name).
pub struct BoardGroup {
    pub name: String,
    pub columns: Vec<DatasetRow>,
    /// Every group's name, the default first: what a board offers to choose from.
    pub names: Vec<String>,
}

fn default_group(datasets: &[DatasetRow]) -> Group {
    let names: Vec<String> = core_datasets(datasets)
        .into_iter()
        .map(|d| d.name)
        .collect();
    Group {
        name: DEFAULT_GROUP.to_string(),
        default: true,
        datasets: names.clone(),
        served: names,
    }
}

fn stored_group(g: GroupRow, datasets: &[DatasetRow]) -> Group {
    Group {
        served: g
            .datasets
            .iter()
            .filter(|m| datasets.iter().any(|d| &d.name == *m))
            .cloned()
            .collect(),
        name: g.name,
        default: false,
        datasets: g.datasets,
    }
}

/// Every group, the default first, then the stored ones in the order they were created.
pub async fn all(app: &App) -> AppResult<Vec<Group>> {
    let datasets = app.store.datasets().await?;
    let stored = app.store.groups().await?;
    Ok(std::iter::once(default_group(&datasets))
        .chain(stored.into_iter().map(|g| stored_group(g, &datasets)))
        .collect())
}

/// The group a board asks for (`None` or empty: the default) among `datasets` (those served);
/// an unknown name is an error naming it and the groups there are.
pub async fn of_board(
    app: &App,
    asked: Option<&str>,
    datasets: &[DatasetRow],
) -> AppResult<BoardGroup> {
    let stored = app.store.groups().await?;
    let names: Vec<String> = std::iter::once(DEFAULT_GROUP.to_string())
        .chain(stored.iter().map(|g| g.name.clone()))
        .collect();
    let asked = asked.map(str::trim).filter(|n| !n.is_empty());
    let group = match asked {
        None | Some(DEFAULT_GROUP) => default_group(datasets),
        Some(name) => match stored.into_iter().find(|g| g.name == name) {
            Some(g) => stored_group(g, datasets),
            None => {
                return Err(AppError::Unknown(format!(
                    "unknown group `{name}` (from the parameter `group`): the groups are {}",
                    names.join(", ")
                )));
            }
        },
    };
    Ok(BoardGroup {
        columns: datasets
            .iter()
            .filter(|d| group.served.contains(&d.name))
            .cloned()
            .collect(),
        name: group.name,
        names,
    })
}

/// The members `datasets` names, checked, without repeats, by name; at least one.
fn members(datasets: &[String]) -> AppResult<Vec<DatasetName>> {
    if datasets.len() > MAX_MEMBERS {
        return Err(AppError::BadRequest(format!(
            "a group names at most {MAX_MEMBERS} datasets"
        )));
    }
    let mut out = Vec::new();
    for d in datasets {
        let name = DatasetName::parse(d)?;
        if !out.contains(&name) {
            out.push(name);
        }
    }
    if out.is_empty() {
        return Err(AppError::BadRequest(
            "field `datasets` must name at least one dataset".into(),
        ));
    }
    out.sort_by(|a, b| a.as_str().cmp(b.as_str()));
    Ok(out)
}

/// Creates group `name` of `datasets`, or replaces the members of the group of that name, and
/// records it; returns the group as readers now see it and whether it is new. The default
/// group's members are the core datasets, so they must be served.
pub async fn save(
    app: &App,
    actor: &User,
    name: &str,
    datasets: &[String],
) -> AppResult<(Group, bool)> {
    let name = GroupName::parse(name)?;
    let members = members(datasets)?;
    let created = if name.as_str() == DEFAULT_GROUP {
        let names: Vec<String> = members.iter().map(|m| m.as_str().to_string()).collect();
        let unknown = app.store.set_core_datasets(&names).await?;
        if !unknown.is_empty() {
            return Err(AppError::BadRequest(format!(
                "the default group `{DEFAULT_GROUP}` is the core datasets, which must be served: \
                 {} not served here",
                unknown.join(", ")
            )));
        }
        false
    } else {
        app.store.save_group(&name, &members).await?
    };
    let listed: Vec<&str> = members.iter().map(DatasetName::as_str).collect();
    app.store
        .audit(
            actor.id,
            AdminAction::SaveGroup,
            &format!("{name}: {}", listed.join(", ")),
        )
        .await?;
    let group = all(app)
        .await?
        .into_iter()
        .find(|g| g.name == name.as_str())
        .ok_or_else(|| AppError::Internal(format!("group {name} missing after saving it")))?;
    Ok((group, created))
}

/// Deletes group `name` and records it. The default group stays: it is the core datasets.
pub async fn delete(app: &App, actor: &User, name: &str) -> AppResult<()> {
    let name = GroupName::parse(name)?;
    if name.as_str() == DEFAULT_GROUP {
        return Err(AppError::BadRequest(format!(
            "the default group `{DEFAULT_GROUP}` cannot be deleted: it is the core datasets; \
             change its members instead"
        )));
    }
    if !app.store.delete_group(&name).await? {
        return Err(AppError::Unknown(format!("unknown group `{name}`")));
    }
    app.store
        .audit(actor.id, AdminAction::DeleteGroup, name.as_str())
        .await?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dataset(name: &str, core: Option<bool>) -> DatasetRow {
        DatasetRow {
            core,
            ..DatasetRow::named(crate::domain::DatasetId::new(0), name)
        }
    }

    fn names(datasets: &[DatasetRow]) -> Vec<String> {
        core_datasets(datasets)
            .into_iter()
            .map(|d| d.name)
            .collect()
    }

    #[test]
    fn the_demo_is_core_only_alone_unless_set() {
        assert_eq!(names(&[dataset(DEMO_DATASET, None)]), [DEMO_DATASET]);
        let both = [dataset("lmo", None), dataset(DEMO_DATASET, None)];
        assert_eq!(names(&both), ["lmo"]);
        let set = [
            dataset("lmo", Some(false)),
            dataset(DEMO_DATASET, Some(true)),
        ];
        assert_eq!(names(&set), [DEMO_DATASET]);
    }
}
