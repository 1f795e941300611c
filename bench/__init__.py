"""Benchmarks and their drawings: they measure the other layers and report numbers; nothing imports them.

| module | command | measures |
|---|---|---|
| `command` | `planhrc bench` | one run of the parts below it asks for, every file of it marked with the run |
| `grid` | `planhrc bench [--replan]` | the paper's planning grid and the re-planning latency, beside packaged planners |
| `scale` | `planhrc bench --scale` | how the in-process stages grow with links and orientations |
| `bimanual` | `planhrc bench --bimanual[-only]` | the bimanual family (`bimanual_tasks`): the chain beside SymK, BFWS, LAMA |
| `large` | `python -m planhrc.bench.large` | re-planning perceptions of 50 x 36 and 200 x 12 absolute objects over HTTP, against the deadline |
| `field` | `python -m planhrc.bench.field` | files in the paper's benchmark styles: how many are VAL-valid in-process |
| `service` | `planhrc service-bench` | the KB service over HTTP with a long history, contention and refusals |
| `ordering` | `python -m planhrc.bench.ordering` | `ordering.order_moves` on long chains |
| `replay` | `python -m planhrc.bench.replay` | grounding: the replay of a plan (cold and warm) and the planner's `ground_task` |
| `plots` | `python -m planhrc.bench.plots` | the box plots of the grid's CSV |
| `tables` | `python -m planhrc.bench.tables` | the README's planning, re-planning and bimanual tables from one run's files |
"""
