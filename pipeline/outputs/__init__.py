"""What a run gives its readers: the report and its figures (:mod:`.report`, :mod:`.figures`,
:mod:`.render`, :mod:`.colours`), rerun recordings (:mod:`.recording`, :mod:`.trial_recording`),
grasp files for other tools and datasets (:mod:`.export` which trials and poses,
:mod:`.export_runs` the runs on disk, :mod:`.export_files` the writers and reader,
:mod:`.replay`, :mod:`.grasp_sets`) and the grading of such files (:mod:`.evaluate`)."""
