"""Input/output: the stage-file layer (names, table, provenance, digests, writes, locks), HDF5+XDMF.

The stage-file layer, bottom-up (a module imports only those before it in this list):

* :mod:`.files` -- every file name of an output folder, spelled once;
* :mod:`.temp_names` -- the temporary name of a file while it is written, stale ones removed;
* :mod:`.digests` -- content digests (the same on any number of ranks) and their records;
* :mod:`.atomic` -- checked atomic writes (temporary name, space reserved, fsync, rename,
  record);
* :mod:`.locks` -- the lock of an output folder;
* :mod:`.products` -- the table of stage files: stage, format, case keys, upstream files;
* :mod:`.provenance` -- what each file records, and the reuse verdict;
* :mod:`.formats` -- one module per file format: its layout, its data check and, where
  they belong to this layer, its writer and reader;
* :mod:`.stage_checks` -- the data check of each stage file (the table of
  :mod:`.formats`' checks);
* :mod:`.run_record` -- ``run.json``, the record of every command run into a folder;
* :mod:`.stage_outputs` -- the stages' result types (the API's results inherit their
  fields; light: no numpy, no stage module);
* :mod:`.stage_protocol` -- the stage protocol and its runner (the stages' one way in).

Beside them: :mod:`.parallel_h5` (collective HDF5) and :mod:`.xdmf` (the ParaView views),
which the formats' writers use.
"""
