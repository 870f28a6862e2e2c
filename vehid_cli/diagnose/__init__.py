"""Close the loop: residual analysis, attribution of the residual to a missing effect, a mis-set known parameter
or a fault of the measurement chain, and the augmentation loop that adds it and re-fits. The loop is generic
(`subject.Subject`, `loop.close`); each system builds its subject (`systems.<name>.diagnosis`) and `vehid diagnose`
reaches it through `systems.diagnose_config`."""
