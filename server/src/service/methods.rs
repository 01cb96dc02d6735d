//! What a method's owner does with it: state its details, and choose which submission is its
//! entry on a dataset. Only the owner (or an administrator) may; anyone else who can see the
//! method is refused (403), and a method or submission they cannot see answers as missing.

use crate::app::App;
use crate::domain::{MethodForm, MethodId, SubmissionId, UserId};
use crate::error::{AppError, AppResult};
use crate::store::accounts::User;
use crate::store::methods::MethodRow;

fn may_change(user: &User, owner: Option<UserId>) -> bool {
    user.is_admin || owner == Some(user.id)
}

/// Replaces the details `form` gives (the others stay) and returns the method as stored.
pub async fn edit(app: &App, user: &User, id: MethodId, form: MethodForm) -> AppResult<MethodRow> {
    let method = app.store.method(id).await?.ok_or(AppError::NotFound)?;
    if !may_change(user, method.owner_id) {
        let public = !app.store.public_submissions_of_method(id).await?.is_empty();
        return Err(if public {
            AppError::Forbidden("only the method's owner may change it".into())
        } else {
            AppError::NotFound
        });
    }
    let details = form.parse(method.as_form())?;
    app.store.set_method_details(id, &details).await?;
    app.store.method(id).await?.ok_or(AppError::NotFound)
}

/// Pins a submission as its method's entry on its dataset (for every protocol), or unpins it:
/// the best public finished submission is the entry again.
pub async fn pin(
    app: &App,
    user: &User,
    submission_id: SubmissionId,
    pinned: bool,
) -> AppResult<()> {
    let submission = app
        .store
        .submission(submission_id)
        .await?
        .ok_or(AppError::NotFound)?;
    if !may_change(user, submission.owner_id) {
        return Err(if submission.is_public() {
            AppError::Forbidden("only the method's owner may choose its entry".into())
        } else {
            AppError::NotFound
        });
    }
    app.store.set_pinned(submission_id, pinned).await?;
    Ok(())
}
