"""Farm batch on a Flamenco Manager (docs/farm.md): chunk plans of long recordings, the Manager's REST
client and the follow-up of a submitted job (re-submitting failed chunks).  No bpy: the batch command,
the panel and the benchmarks share it."""
