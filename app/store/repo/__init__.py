"""Repository functions: every query the API and the worker make, by concern.

- ``classes``: the attribute vocabulary, classes and their samples, withdrawals and new
  descriptions;
- ``versions``: model versions and the bundle bytes they point to;
- ``jobs``: the worker's queue;
- ``keys``: API keys and Idempotency-Key records;
- ``encoding``: how vectors, samples and metrics are written down (no queries).

Every public name is re-exported here, so callers write ``from app.store import repo``
and ``repo.add_class(...)`` whichever module holds it. Functions take a Session and
leave committing to the caller unless their name or docstring says otherwise, so one
request or one retrain is one transaction.
"""

from app.framework.jsonable import jsonable
from app.store.repo.classes import (
    LIVE_CLASS,
    LIVE_SAMPLE,
    add_attributes,
    add_class,
    add_dataset_samples,
    add_sample,
    attribute_names,
    class_by_key,
    class_by_name,
    class_ids_by_name,
    class_names_of_samples,
    demote_classes,
    get_class,
    get_sample,
    list_classes,
    list_samples,
    promote_classes,
    redescribe_class,
    revive_class,
    sample_counts,
    sample_record,
    samples_by_id,
    samples_of,
    withdraw_class,
    withdraw_sample,
)
from app.store.repo.encoding import (
    attribute_labels,
    decode,
    decode_sample,
    decode_trial,
    encode,
    encode_sample,
    encode_trial,
    key_vector,
    vector_key,
)
from app.store.repo.jobs import (
    FINISHED_JOB_STATUSES,
    add_job,
    claim_queued_jobs,
    finish_jobs,
    finished_job_ids,
    get_job,
    get_jobs,
    jobs_by_status,
    jobs_finished_since,
    jobs_pending,
    latest_registrations,
    list_jobs,
    registration_failed,
    requeue_running,
    sample_enrolments,
)
from app.store.repo.keys import (
    KEY_PREFIX,
    SCOPES,
    add_idempotency,
    api_key_table,
    create_api_key,
    get_idempotency,
    hash_key,
    list_api_keys,
    purge_idempotency,
    revoke_api_key,
)
from app.store.repo.versions import (
    BUNDLE_READ_BYTES,
    activate,
    active_version,
    active_version_number,
    add_version,
    bundle_data,
    get_version,
    list_versions,
    store_bundle,
    stored_model_figures,
)

__all__ = [
    # classes
    "LIVE_CLASS",
    "LIVE_SAMPLE",
    "add_attributes",
    "add_class",
    "add_dataset_samples",
    "add_sample",
    "attribute_names",
    "class_by_key",
    "class_by_name",
    "class_ids_by_name",
    "class_names_of_samples",
    "demote_classes",
    "get_class",
    "get_sample",
    "list_classes",
    "list_samples",
    "promote_classes",
    "redescribe_class",
    "revive_class",
    "sample_counts",
    "sample_record",
    "samples_by_id",
    "samples_of",
    "withdraw_class",
    "withdraw_sample",
    # encoding
    "attribute_labels",
    "decode",
    "decode_sample",
    "decode_trial",
    "encode",
    "encode_sample",
    "encode_trial",
    "jsonable",
    "key_vector",
    "vector_key",
    # jobs
    "FINISHED_JOB_STATUSES",
    "add_job",
    "claim_queued_jobs",
    "finish_jobs",
    "finished_job_ids",
    "get_job",
    "get_jobs",
    "jobs_by_status",
    "jobs_finished_since",
    "jobs_pending",
    "latest_registrations",
    "list_jobs",
    "registration_failed",
    "requeue_running",
    "sample_enrolments",
    # keys
    "KEY_PREFIX",
    "SCOPES",
    "add_idempotency",
    "api_key_table",
    "create_api_key",
    "get_idempotency",
    "hash_key",
    "list_api_keys",
    "purge_idempotency",
    "revoke_api_key",
    # versions
    "BUNDLE_READ_BYTES",
    "activate",
    "active_version",
    "active_version_number",
    "add_version",
    "bundle_data",
    "get_version",
    "list_versions",
    "store_bundle",
    "stored_model_figures",
]
