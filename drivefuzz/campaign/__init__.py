"""Campaigns: one seed's fuzz loop (:mod:`~drivefuzz.campaign.job`), a campaign directory
(:mod:`~drivefuzz.campaign.fuzz`), batches of cells (:mod:`~drivefuzz.campaign.batch`) and Dask clusters
(:mod:`~drivefuzz.campaign.cluster`).
"""
