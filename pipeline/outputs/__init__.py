"""What a run gives its readers: the report and its figures (:mod:`.report`, :mod:`.figures`,
:mod:`.render`, :mod:`.colours`), rerun recordings (:mod:`.recording`), grasp files for other
tools and datasets (:mod:`.export`, :mod:`.grasp_sets`) and the grading of such files
(:mod:`.evaluate`)."""
