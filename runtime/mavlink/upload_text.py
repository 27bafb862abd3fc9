"""The line ``gainlink mavlink upload`` prints for what an upload did (:class:`.upload.UploadResult`)."""

from __future__ import annotations

from typing import Any


def upload_summary(artifact: Any, res: Any) -> str:
    """One line: what would change (a dry run), what was set, committed and persisted, or that nothing needed
    uploading (the vehicle already held every value and the set in force), never a word for work not done.

    A storage request the vehicle acknowledged after nothing changed is reported as such, not as "persisted":
    gainlink's firmware writes its flash only when it holds another set, and no other vehicle says whether it did.
    """
    target = f"vehicle {res.vehicle.describe()}"
    if res.dry_run:
        return (
            f"dry run: {len(res.changes)} parameter(s) would change, {res.unchanged} already match "
            f"({target}, {res.encoding.value} integers)"
        )
    name = f"{artifact.name} sha256:{artifact.sha256[:12]}"
    cost = f"({res.sent} sent, {res.retries} retries, {res.seconds:.3f} s)"
    if not res.changes and not res.committed:
        kept = (
            "; its storage acknowledged the request to keep them (a write only if it held another set)"
            if res.persisted
            else ""
        )
        return f"nothing to upload: {target} already holds {name} ({res.unchanged} parameters match){kept} {cost}"
    what = [f"{res.verified} set(s) verified", f"{res.unchanged} unchanged", *_commit_words(res)]
    if res.persisted:
        what.append("persisted")
    return f"uploaded {name} to {target}: {', '.join(what)} {cost}"


def _commit_words(res: Any) -> list[str]:
    """What the summary may say of the commit: confirmed by a gainlink node, or only echoed by another vehicle."""
    if res.committed:
        return ["gain set committed (the node's AUTOPILOT_VERSION uid is its CRC-32)"]
    if res.hash_set:
        return [
            "GL_HASH echoed, commit NOT confirmed (the vehicle does not identify as a gainlink node: it holds the "
            "values, nothing shows that its loop runs them)"
        ]
    return []
