"""Reports: of campaign files (`campaigns`: tables in several formats, provenance), of a diagnosis (`diagnosis`), a
design, the figures and the HTML page. Empty, so that `vehid diagnose`, which prints through `report.diagnosis`,
does not load the campaign files' reader (and with it every system and HDF5) at start-up."""
