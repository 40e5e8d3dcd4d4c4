"""Skip what a scene does not need: the region of interest (`roi`), which skips run (`settings`), passes only
at pixels the filter can keep (`keep_skip`) and BP's coarse-to-fine depth search (`bp_search`).
"""
