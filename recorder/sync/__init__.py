"""``thermcap sync``: a vehicle's recordings to an object store over a link that drops.

``plan`` says what goes and in what order; ``journal`` keeps every upload's state on disk;
``rate`` keeps the bandwidth cap; ``targets`` speak to the store (S3 multipart through boto3, or
a mounted directory); ``engine`` runs it and reads the cloud's receipts back.
"""
