"""Batches of takes on a Dask cluster: `usdfacedyn batch` and `simulate` with one task per take.

A batch runs facedyn's own commands (import, stabilize, remove, synthesize, preview) for
many captures, one Dask task per (take, step) chained along the steps, on an embedded local
cluster or an existing one (facedyn.batch.cluster). Each step is skipped when its output
and provenance say it is already done (facedyn.batch.state), so a batch is resumable; a
failing take is reported and the others go on. facedyn.batch.cluster_corpus builds a simulated
corpus with one task per take. Nothing here imports pxr: the steps go through the CLI.

On a render farm, start the workers through the farm's scheduler with dask-jobqueue
(``pip install dask-jobqueue``; SLURMCluster, PBSCluster, SGECluster take the same
arguments), one thread per worker, and pass the scheduler's address to ``--scheduler``:

    from dask_jobqueue import SLURMCluster
    cluster = SLURMCluster(queue="facial", cores=1, processes=1, memory="8GB", walltime="04:00:00")
    cluster.scale(jobs=50)
    print(cluster.scheduler_address)   # usdfacedyn batch shots.txt -o out --scheduler tcp://...

(keep that Python process running while the batch runs). Without a farm: ``dask scheduler``
on one machine and ``dask worker tcp://HOST:8786 --nthreads 1 --nworkers N`` on each
other. Every worker must see OUTDIR, the captures and the models at the same paths.
"""
