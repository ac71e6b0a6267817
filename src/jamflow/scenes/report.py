"""What a plan will cost, printed before a run: per rule the jobs, threads, memory and runtime
requests, and the scene's total expected core-hours."""

from __future__ import annotations

from .plan import Plan
from .resources import request_mb, request_minutes

__all__ = ["cost_report"]


def cost_report(plan: Plan) -> list[str]:
    """Lines: one per rule (jobs, threads, memory and runtime requests), cluster groups, the total.

    The total is the expected CPU time of every job (threads x expected seconds), not the
    requests, which are :data:`jamflow.scenes.resources.RUNTIME_SAFETY` times longer.
    """
    rows: dict[str, list] = {}
    for job in plan.jobs.values():
        rows.setdefault(job.rule, []).append(job)
    width = max((len(r) for r in rows), default=4)
    lines = [f"{'rule':<{width}}  jobs  threads  mem_mb  runtime [min]  expected CPU [h]"]
    total = 0.0
    for rule, jobs in rows.items():
        minutes = sorted({request_minutes(j.cpu_s) for j in jobs})
        spread = f"{minutes[0]}" if len(minutes) == 1 else f"{minutes[0]}-{minutes[-1]}"
        hours = sum(j.threads * j.cpu_s for j in jobs) / 3600
        total += hours
        lines.append(f"{rule:<{width}}  {len(jobs):>4}  {max(j.threads for j in jobs):>7}  "
                     f"{max(request_mb(j.mem_mb) for j in jobs):>6}  {spread:>13}  {hours:>16.3g}")
    groups = {j.group for j in plan.jobs.values() if j.group}
    grouped = sum(1 for j in plan.jobs.values() if j.group)
    lines.append(f"cluster groups: {grouped} jobs of {len({j.unit for j in plan.jobs.values() if j.unit})} "
                 f"packings in {len(groups)} groups (about {plan.scene.resources.get('group_minutes', 60):g} "
                 "CPU-minutes each); light rules run on the submitting host")
    lines.append(f"scene {plan.scene.name} at {plan.scene.scale} scale: {len(plan.jobs)} jobs, "
                 f"{total:.3g} core-hours expected")
    lines += [f"note: {n}" for n in plan.notes]
    return lines
